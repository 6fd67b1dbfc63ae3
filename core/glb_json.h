/* A .glb with its JSON chunk rewritten: the pre-passes that make a file
 * parseable by Debian's tinygltf (draco_decode.h, meshopt_decode.h) work on
 * the JSON text; for a .glb they go through here. */
#ifndef DR_GLB_JSON_H
#define DR_GLB_JSON_H

#ifndef __cplusplus
#error "glb_json.h is a C++ interface"
#endif

#include <string>
#include <vector>

/* The .glb with rewrite() applied to its JSON chunk (padded to 4 bytes, the
 * lengths updated, the BIN chunk after it as it was); empty when rewrite()
 * changed nothing (it returns false) or the container is malformed
 * (tinygltf then says how). */
std::vector<unsigned char> dr_glb_rewrite_json(const std::vector<unsigned char> &glb, bool (*rewrite)(std::string &));

#endif
