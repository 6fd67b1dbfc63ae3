/* KHR_draco_mesh_compression through libdraco (see draco_decode.h). */
#include "draco_decode.h"

#include <cstring>

#include <nlohmann/json.hpp>

#include "glb_json.h"
#include "json_release.h"

#include <draco/compression/decode.h>
#include <draco/mesh/mesh.h>

bool dr_draco_decode(const unsigned char *data, size_t size, dr_draco_mesh *out, std::string *err)
{
    try {
        draco::DecoderBuffer buf;
        buf.Init(reinterpret_cast<const char *>(data), size);
        draco::Decoder decoder;
        auto res = decoder.DecodeMeshFromBuffer(&buf);
        if (!res.ok()) {
            *err = res.status().error_msg_string();
            return false;
        }
        const draco::Mesh &mesh = *res.value();
        out->n_points = mesh.num_points();
        out->indices.resize(size_t(mesh.num_faces()) * 3);
        for (draco::FaceIndex f(0); f < mesh.num_faces(); ++f)
            for (int k = 0; k < 3; k++) {
                uint32_t v = mesh.face(f)[k].value();
                if (v >= out->n_points) {   /* draco checks this; the tracer must be able to trust it */
                    *err = "a face refers to a point that does not exist";
                    return false;
                }
                out->indices[size_t(f.value()) * 3 + size_t(k)] = v;
            }
        for (int a = 0; a < mesh.num_attributes(); a++) {
            const draco::PointAttribute *pa = mesh.attribute(a);
            dr_draco_attribute da;
            da.unique_id = int(pa->unique_id());
            da.components = pa->num_components();
            if (da.components < 1 || da.components > 4) continue;   /* nothing glTF maps */
            da.values.resize(out->n_points * size_t(da.components));
            for (draco::PointIndex p(0); p < mesh.num_points(); ++p)
                if (!pa->ConvertValue<float>(pa->mapped_index(p), int8_t(da.components),
                                             &da.values[size_t(p.value()) * size_t(da.components)])) {
                    *err = "attribute " + std::to_string(da.unique_id) + " cannot be converted to float";
                    return false;
                }
            out->attributes.push_back(std::move(da));
        }
        return true;
    } catch (const std::bad_alloc &) {
        *err = "out of memory";
        return false;
    }
}

/* ---- the glTF side of KHR_draco_mesh_compression (loader and writer) ---- */

/* tinygltf (Debian's is built without Draco) refuses a primitive whose
 * "indices" accessor has no bufferView, as KHR_draco_mesh_compression's are:
 * those indices live in the compressed stream (gltf_load.cpp's decode_draco). Such primitives
 * lose "indices" in the copy of the JSON that tinygltf parses. False when
 * nothing needed rewriting (then tinygltf reads the file itself, as ever). */
bool dr_draco_strip_indices(std::string &json_text)
{
    if (json_text.find("KHR_draco_mesh_compression") == std::string::npos) return false;
    DrJsonDocument doc(nlohmann::json::parse(json_text, nullptr, /*allow_exceptions=*/false));
    nlohmann::json &j = doc.j;
    if (j.is_discarded() || !j.is_object()) return false;   /* tinygltf reports the syntax error */
    auto meshes = j.find("meshes");
    if (meshes == j.end() || !meshes->is_array()) return false;
    bool changed = false;
    for (auto &m : *meshes) {
        if (!m.is_object() || !m.contains("primitives") || !m["primitives"].is_array()) continue;
        for (auto &p : m["primitives"]) {
            if (!p.is_object() || !p.contains("extensions") || !p["extensions"].is_object() ||
                !p["extensions"].contains("KHR_draco_mesh_compression"))
                continue;
            changed |= p.erase("indices") > 0;
        }
    }
    if (changed) json_text = j.dump();
    return changed;
}

/* A .glb with its JSON chunk rewritten by dr_draco_strip_indices; empty when
 * nothing changed (or the container is malformed: tinygltf says how). */
std::vector<unsigned char> dr_glb_strip_draco_indices(const std::vector<unsigned char> &glb)
{
    return dr_glb_rewrite_json(glb, dr_draco_strip_indices);
}

