/* KHR_draco_mesh_compression: a thin C++ shim over Debian's libdraco, used
 * by gltf_load.cpp and gltf_write.cpp (the only file that includes draco's headers is
 * draco_decode.cpp, so its templates stay out of the loader). */
#ifndef DR_DRACO_DECODE_H
#define DR_DRACO_DECODE_H

#ifndef __cplusplus
#error "draco_decode.h is a C++ interface (core/gltf_load.cpp)"
#endif

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

/* One decoded attribute, per point, converted to float (draco applies the
 * normalised-integer rule of attributes flagged normalised). */
struct dr_draco_attribute {
    int unique_id;                /* the id the glTF extension's "attributes" map names */
    int components;               /* 1..4 */
    std::vector<float> values;    /* components per point */
};

struct dr_draco_mesh {
    size_t n_points = 0;
    std::vector<uint32_t> indices;                  /* 3 per face, each < n_points */
    std::vector<dr_draco_attribute> attributes;
};

/* Decodes a Draco-compressed triangle mesh from data[0..size). Returns false
 * with *err set (draco's message) when the bytes are not a valid Draco mesh. */
bool dr_draco_decode(const unsigned char *data, size_t size, dr_draco_mesh *out, std::string *err);

/* tinygltf (Debian's is built without Draco) refuses a primitive whose
 * "indices" accessor has no bufferView, as KHR_draco_mesh_compression's are.
 * These rewrite the JSON tinygltf is given so that such primitives have no
 * "indices" (the loader decodes them from the stream; the writer puts them
 * back). dr_draco_strip_indices: false when nothing needed rewriting.
 * dr_glb_strip_draco_indices: the .glb with its JSON chunk rewritten, empty
 * when nothing changed or the container is malformed. */
bool dr_draco_strip_indices(std::string &json_text);
std::vector<unsigned char> dr_glb_strip_draco_indices(const std::vector<unsigned char> &glb);

#endif
