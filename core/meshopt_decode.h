/* EXT_meshopt_compression (meshoptimizer's vertex and index codecs, as
 * gltfpack -c and glTF-Transform write them), decoded with Debian's
 * libmeshoptimizer. Used by gltf_load.cpp and gltf_write.cpp.
 *
 * A compressed bufferView names, in its extension, where its compressed
 * bytes are (buffer, byteOffset, byteLength) and how to decode them (count,
 * byteStride, mode, filter); its own buffer may be a "fallback" buffer that
 * has no bytes at all ({"byteLength": N, "extensions": {"EXT_meshopt_
 * compression": {"fallback": true}}}). tinygltf refuses such a buffer in a
 * .gltf (no uri) and would copy the BIN chunk into it in a .glb, so the JSON
 * it is given is rewritten first (dr_meshopt_mark_fallbacks); after parsing,
 * dr_meshopt_decode decodes every compressed bufferView into a buffer of its
 * own and points the bufferView there, so the rest of the loader reads plain
 * bytes. */
#ifndef DR_MESHOPT_DECODE_H
#define DR_MESHOPT_DECODE_H

#ifndef __cplusplus
#error "meshopt_decode.h is a C++ interface (core/gltf_load.cpp, core/gltf_write.cpp)"
#endif

#include <string>
#include <vector>

namespace tinygltf {
class Model;
}

/* Gives every fallback buffer without a uri a data URI of one zero byte
 * (its bytes are never read: dr_meshopt_decode points every bufferView on
 * it elsewhere). False when nothing needed rewriting. */
bool dr_meshopt_mark_fallbacks(std::string &json_text);
/* The same on a .glb's JSON chunk: the rewritten .glb, empty when nothing
 * changed or the container is malformed (tinygltf then says how). */
std::vector<unsigned char> dr_glb_meshopt_mark_fallbacks(const std::vector<unsigned char> &glb);

/* Decodes every bufferView with EXT_meshopt_compression into a new buffer
 * appended to model.buffers (byteOffset 0, byteLength count x byteStride,
 * the extension removed). "" on success, else what is wrong, starting with
 * the JSON path of the bufferView. */
std::string dr_meshopt_decode(tinygltf::Model &model);

/* After dr_meshopt_decode, for a file written back without the extension:
 * removes the buffers no bufferView uses any more (the compressed bytes and
 * the fallbacks), renumbering the bufferViews' buffer indices, and takes
 * EXT_meshopt_compression out of extensionsUsed and extensionsRequired. */
void dr_meshopt_drop_compressed_buffers(tinygltf::Model &model);

#endif
