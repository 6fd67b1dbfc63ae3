/* Temporary files a killed drender leaves behind. Every output is written to
 * a temporary name beside it and renamed into place, so a SIGKILL never
 * leaves a partial file under the real name -- but it can leave the
 * temporary. optimize calls this when it starts (and on --resume), so that
 * they do not pile up in the progress directory. */
#ifndef DR_CLI_STALE_TEMPS_H
#define DR_CLI_STALE_TEMPS_H

/* Removes from DIR the temporaries of drender's atomic writes whose writer
 * is gone: NAME.tmpPID and .NAME.tmpPID.EXT (checkpoints, images) of
 * processes that no longer exist, loss.csv.tmp and .loss.tmp.png; and, when
 * OUTPUT is not NULL, the glTF writer's .BASE.tmpXXXXXX directories beside
 * OUTPUT. Returns how many entries were removed. */
int cli_remove_stale_temps(const char *dir, const char *output);

#endif
