/* Resource limits of the command line: how much memory a command will need,
 * estimated from its options and the loaded scene before the big buffers are
 * allocated, against how much the machine has. A request that cannot fit is
 * refused with a message naming the option (exit 2), never left to the OOM
 * killer; the estimate is printed in --json as "memory_estimate_bytes".
 *
 * Each command calls its cli_limits_CMD() hook once, after the scene and the
 * parameters are known and before it allocates images or gradient buffers.
 * The hooks return -1 to go on, or an exit code after printing the message. */
#ifndef DR_CLI_MEM_LIMITS_H
#define DR_CLI_MEM_LIMITS_H

#include <stdbool.h>
#include <stdint.h>
#include <stdio.h>

struct dr_scene;
struct dr_param_set;
struct grad_common;

/* Bytes drender lets itself use: $DRENDER_MEM_LIMIT when set (a number of
 * bytes with an optional K, M, G or T suffix, powers of 1024), else the
 * machine's physical memory (MemTotal of /proc/meminfo) or the cgroup's
 * memory.max when lower. */
uint64_t cli_mem_limit(void);
/* "123", "64K", "1.5G", "2T" -> bytes; false when malformed or zero. */
bool cli_parse_bytes(const char *text, uint64_t *out);
/* Once, from main(): hands the limit to core's image reader (textures,
 * targets and environment maps larger than it are refused before decoding). */
void cli_limits_init(void);

/* Decoded size of the scene: mesh, images (data and linear copies), the
 * environment map, the acceleration structure (approximate). */
uint64_t cli_mem_scene(const struct dr_scene *scene);


int cli_limits_render(const struct dr_scene *scene, int width, int height, int spp, int threads);
/* grad: reverse (with --target) or forward mode; K batches (refused when
 * batches_given and K > --spp), --batch paths (tape); parts: the run
 * estimates the standard error's parts (dr_reverse_parts). */
int cli_limits_grad(const struct grad_common *g, const struct dr_scene *scene, const struct dr_param_set *ps,
                    bool reverse, int batches, bool batches_given, int64_t batch, bool parts);
int cli_limits_fdcheck(const struct grad_common *g, const struct dr_scene *scene, const struct dr_param_set *ps,
                       int batches);
/* optimize: the targets' pixels in all and the largest target's, and how many targets. */
int cli_limits_optimize(const struct grad_common *g, const struct dr_scene *scene, const struct dr_param_set *ps,
                        uint64_t target_pixels, uint64_t max_pixels, int n_targets);

/* compare: reverse or forward mode, g's size and largest max depth; tape when
 * the tape estimator is among those compared, mis when mis sampling is. */
int cli_limits_compare(const struct grad_common *g, const struct dr_scene *scene, const struct dr_param_set *ps,
                       bool reverse, bool tape, bool mis);

/* The estimate of the last cli_limits_* call, in bytes (0 before any). */
uint64_t cli_mem_estimate(void);
/* Writes ', "memory_estimate_bytes": N' into a JSON object being printed. */
void cli_json_memory_estimate(FILE *f);

#endif
