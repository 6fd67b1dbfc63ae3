/* EXT_meshopt_compression through libmeshoptimizer (see meshopt_decode.h). */
#include "meshopt_decode.h"

#include <algorithm>
#include <cstdarg>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <map>
#include <set>

#include <meshoptimizer.h>
#include <nlohmann/json.hpp>
#include <tiny_gltf.h>

#include "glb_json.h"
#include "json_release.h"

namespace {

const char kExt[] = "EXT_meshopt_compression";

bool is_fallback(const nlohmann::json &b)
{
    if (!b.is_object() || b.contains("uri")) return false;
    auto e = b.find("extensions");
    if (e == b.end() || !e->is_object()) return false;
    auto m = e->find(kExt);
    return m != e->end() && m->is_object() && m->value("fallback", false) == true;
}

std::string strf(const char *fmt, ...) __attribute__((format(printf, 1, 2)));
std::string strf(const char *fmt, ...)
{
    char buf[512];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(buf, sizeof buf, fmt, ap);
    va_end(ap);
    return buf;
}

/* An integer member of the extension object (-1: absent or not a non-negative integer). */
long long ext_int(const tinygltf::Value &o, const char *key)
{
    if (!o.Has(key)) return -1;
    const tinygltf::Value &v = o.Get(key);
    if (v.IsInt()) return v.Get<int>() >= 0 ? v.Get<int>() : -1;
    if (v.IsNumber()) {
        const double d = v.GetNumberAsDouble();
        return d >= 0 && d <= 9.0e15 && d == double((long long)d) ? (long long)d : -1;
    }
    return -1;
}

std::string ext_string(const tinygltf::Value &o, const char *key, const char *def)
{
    return o.Has(key) && o.Get(key).IsString() ? o.Get(key).Get<std::string>() : std::string(def);
}

/* One compressed bufferView decoded into out; "" or what is wrong (after the view's path). */
std::string decode_view(const tinygltf::Model &model, const tinygltf::Value &e, std::vector<unsigned char> &out)
{
    const long long buffer = ext_int(e, "buffer"), offset = e.Has("byteOffset") ? ext_int(e, "byteOffset") : 0;
    const long long length = ext_int(e, "byteLength"), stride = ext_int(e, "byteStride"), count = ext_int(e, "count");
    const std::string mode = ext_string(e, "mode", ""), filter = ext_string(e, "filter", "NONE");
    if (buffer < 0 || size_t(buffer) >= model.buffers.size()) return "/buffer: no such buffer";
    if (offset < 0 || length < 0 || stride <= 0 || count < 0)
        return ": byteOffset, byteLength, byteStride and count must be non-negative integers (byteStride above 0)";
    const std::vector<unsigned char> &src = model.buffers[size_t(buffer)].data;
    if (size_t(offset) > src.size() || size_t(length) > src.size() - size_t(offset))
        return strf("/byteLength: %lld bytes from %lld are past the end of buffer %lld (%zu bytes)", length, offset,
                    buffer, src.size());
    /* (meshopt's decoders assert on these: checked first) */
    if (mode == "ATTRIBUTES") {
        if (stride % 4 != 0 || stride > 256) return "/byteStride: ATTRIBUTES need a multiple of 4 up to 256";
    } else if (mode == "TRIANGLES" || mode == "INDICES") {
        if (stride != 2 && stride != 4) return "/byteStride: indices are 2 or 4 bytes";
        if (mode == "TRIANGLES" && count % 3 != 0) return "/count: TRIANGLES need a multiple of 3";
    } else {
        return "/mode: expected ATTRIBUTES, TRIANGLES or INDICES";
    }
    if (filter == "OCTAHEDRAL" ? stride != 4 && stride != 8
        : filter == "QUATERNION" ? stride != 8
        : filter == "EXPONENTIAL" ? stride % 4 != 0
        : filter != "NONE")
        return "/filter: " + filter + (filter == "OCTAHEDRAL" || filter == "QUATERNION" || filter == "EXPONENTIAL"
                                           ? " does not take a byteStride of " + std::to_string(stride)
                                           : " is not a filter (NONE, OCTAHEDRAL, QUATERNION or EXPONENTIAL)");
    /* What the codecs can expand to: 64 decoded bytes per encoded byte for
     * vertices (2 header bits per 16 bytes of a byte channel), less for
     * indices; and 1 GiB per view, as sparse accessors */
    const unsigned long long bytes = (unsigned long long)count * (unsigned long long)stride;
    if (bytes > (1ull << 30) || bytes > 64ull * (unsigned long long)length + 4096)
        return strf("/count: %lld x %lld bytes from %lld compressed bytes is more than the codec can encode or "
                    "drender accepts", count, stride, length);
    out.assign(size_t(bytes), 0);
    const unsigned char *in = src.data() + offset;
    int rc = mode == "ATTRIBUTES"
                 ? meshopt_decodeVertexBuffer(out.data(), size_t(count), size_t(stride), in, size_t(length))
             : mode == "TRIANGLES"
                 ? meshopt_decodeIndexBuffer(out.data(), size_t(count), size_t(stride), in, size_t(length))
                 : meshopt_decodeIndexSequence(out.data(), size_t(count), size_t(stride), in, size_t(length));
    if (rc != 0) return strf(": the compressed bytes do not decode (meshoptimizer error %d)", rc);
    if (filter == "OCTAHEDRAL") meshopt_decodeFilterOct(out.data(), size_t(count), size_t(stride));
    if (filter == "QUATERNION") meshopt_decodeFilterQuat(out.data(), size_t(count), size_t(stride));
    if (filter == "EXPONENTIAL") meshopt_decodeFilterExp(out.data(), size_t(count), size_t(stride));
    return "";
}

}  // namespace

bool dr_meshopt_mark_fallbacks(std::string &json_text)
{
    if (json_text.find(kExt) == std::string::npos) return false;
    DrJsonDocument doc(nlohmann::json::parse(json_text, nullptr, /*allow_exceptions=*/false));
    nlohmann::json &j = doc.j;
    if (j.is_discarded() || !j.is_object()) return false;   /* tinygltf reports the syntax error */
    auto buffers = j.find("buffers");
    if (buffers == j.end() || !buffers->is_array()) return false;
    bool changed = false;
    for (auto &b : *buffers)
        if (is_fallback(b)) {
            b["uri"] = "data:application/octet-stream;base64,AA==";   /* (tinygltf decodes no empty URI) */
            b["byteLength"] = 1;
            changed = true;
        }
    if (changed) json_text = j.dump();
    return changed;
}

std::vector<unsigned char> dr_glb_meshopt_mark_fallbacks(const std::vector<unsigned char> &glb)
{
    return dr_glb_rewrite_json(glb, dr_meshopt_mark_fallbacks);
}

std::string dr_meshopt_decode(tinygltf::Model &model)
{
    for (size_t i = 0; i < model.bufferViews.size(); i++) {
        tinygltf::BufferView &bv = model.bufferViews[i];
        auto it = bv.extensions.find(kExt);
        if (it == bv.extensions.end()) continue;
        const std::string path = strf("/bufferViews/%zu/extensions/%s", i, kExt);
        if (!it->second.IsObject()) return path + ": expected an object";
        tinygltf::Buffer decoded;
        const std::string why = decode_view(model, it->second, decoded.data);
        if (!why.empty()) return path + why;
        const size_t stride = size_t(ext_int(it->second, "byteStride"));
        if (bv.byteStride != 0 && bv.byteStride != stride)
            return strf("/bufferViews/%zu/byteStride: %zu, but the compressed view's is %zu", i, bv.byteStride, stride);
        bv.byteLength = decoded.data.size();
        bv.byteOffset = 0;
        bv.buffer = int(model.buffers.size());
        bv.extensions.erase(it);
        model.buffers.push_back(std::move(decoded));
    }
    return "";
}

void dr_meshopt_drop_compressed_buffers(tinygltf::Model &model)
{
    std::set<int> used;
    for (const tinygltf::BufferView &bv : model.bufferViews) used.insert(bv.buffer);
    std::map<int, int> renumber;
    std::vector<tinygltf::Buffer> kept;
    for (size_t b = 0; b < model.buffers.size(); b++)
        if (used.count(int(b))) {
            renumber[int(b)] = int(kept.size());
            kept.push_back(std::move(model.buffers[b]));
        }
    model.buffers = std::move(kept);
    for (tinygltf::BufferView &bv : model.bufferViews)
        if (renumber.count(bv.buffer)) bv.buffer = renumber[bv.buffer];
    for (std::vector<std::string> *list : {&model.extensionsUsed, &model.extensionsRequired})
        list->erase(std::remove(list->begin(), list->end(), std::string(kExt)), list->end());
}
