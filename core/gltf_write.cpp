/* struct dr_scene + parameter values -> glTF (.gltf + .bin, or .glb), through
 * tinygltf (Debian's shared library: no TINYGLTF_IMPLEMENTATION here).
 *
 * The source file is parsed again (images are not decoded: a no-op image
 * loader), the parameter values are set into the tinygltf::Model, and the model
 * is written with tinygltf into a private temporary directory beside the
 * output; new images are written there by OpenImageIO (image_io.cpp). Only
 * when everything is there are the files renamed into place, resources first
 * and the .gltf/.glb last.
 *
 * Notes on tinygltf 2.7 that shape this file:
 *  - ParseImage does not keep a data: URI in Image::uri (it decodes it and
 *    calls the image loader), so the loader callback re-encodes the bytes into
 *    a data URI, or the writer would turn the image into "bufferView": -1.
 *  - WriteGltfSceneToFile writes buffers to JoinPath(dir, uri) without
 *    decoding the uri, with std::ofstream and no error check after writing;
 *    the files are therefore checked (sizes, GLB length, JSON ending) and
 *    synced before they are renamed.
 *  - UpdateImageObject reduces an image uri to its base name unless the image
 *    writer callback supplies the uri: ours returns the uri unchanged.
 *  - SerializeGltfPerspectiveCamera always writes "zfar", 0 for an infinite
 *    projection, which the validator rejects (VALUE_NOT_IN_RANGE). So the JSON
 *    tinygltf wrote is read back, repaired (fix_json) and written again with
 *    checked I/O; for a .glb the JSON chunk is replaced and the BIN chunk kept.
 *
 * Internally a failure throws `Failure` after dr_set_error(); the extern "C"
 * entry point catches it (and everything else), so no exception escapes. */
#include <tiny_gltf.h>
#include <nlohmann/json.hpp>   /* the JSON library tinygltf itself is built with */

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdarg>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <map>
#include <set>
#include <string>
#include <vector>

#include <dirent.h>
#include <fcntl.h>
#include <strings.h>
#include <sys/stat.h>
#include <unistd.h>

#include "cut_short.h"
#include "error.h"
#include "gltf_write.h"
#include "image_io.h"
#include "medium.h"
#include "draco_decode.h"
#include "meshopt_decode.h"
#include "json_release.h"

namespace {

struct Failure {
    int code;
};

#if defined(__GNUC__)
#define DR_PRINTF(a, b) __attribute__((format(printf, a, b)))
#else
#define DR_PRINTF(a, b)
#endif

DR_PRINTF(1, 2) std::string strf(const char *fmt, ...)
{
    char buf[2048];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(buf, sizeof buf, fmt, ap);
    va_end(ap);
    return buf;
}

bool has_suffix_ci(const std::string &s, const char *suffix)
{
    size_t m = strlen(suffix);
    return s.size() >= m && strcasecmp(s.c_str() + s.size() - m, suffix) == 0;
}

/* "dir/" (with the slash) or "" for a bare file name */
std::string directory_of(const std::string &path)
{
    size_t slash = path.find_last_of('/');
    return slash == std::string::npos ? std::string() : path.substr(0, slash + 1);
}

std::string base_of(const std::string &path)
{
    size_t slash = path.find_last_of('/');
    return slash == std::string::npos ? path : path.substr(slash + 1);
}

std::string join(const std::string &dir, const std::string &name)
{
    return dir.empty() ? name : dir + name;   /* dir ends with '/' */
}

/* ---- URIs ---- */

std::string percent_decode(const std::string &s)
{
    auto hex = [](char c) {
        return c >= '0' && c <= '9' ? c - '0' : c >= 'a' && c <= 'f' ? c - 'a' + 10 : c >= 'A' && c <= 'F' ? c - 'A' + 10 : -1;
    };
    std::string out;
    for (size_t i = 0; i < s.size(); i++) {
        int h, l;
        if (s[i] == '%' && i + 2 < s.size() && (h = hex(s[i + 1])) >= 0 && (l = hex(s[i + 2])) >= 0) {
            out += char(h * 16 + l);
            i += 2;
        } else {
            out += s[i];
        }
    }
    return out;
}

/* A file name as a relative URI reference: unreserved characters stay, the
 * rest is percent-encoded (':' too, so no first segment reads as a scheme). */
std::string percent_encode(const std::string &s)
{
    static const char *hex = "0123456789ABCDEF";
    std::string out;
    for (unsigned char c : s) {
        if ((c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || strchr("-._~/!$&'()*+,;=@", c)) {
            out += char(c);
        } else {
            out += '%';
            out += hex[c >> 4];
            out += hex[c & 15];
        }
    }
    return out;
}


/* RFC 3986 scheme: ALPHA *( ALPHA / DIGIT / "+" / "-" / "." ) ":" before any '/' */
bool has_scheme(const std::string &uri)
{
    size_t colon = uri.find(':');
    if (colon == std::string::npos || colon == 0) return false;
    size_t slash = uri.find('/');
    if (slash != std::string::npos && slash < colon) return false;
    if (!isalpha((unsigned char)uri[0])) return false;
    for (size_t i = 1; i < colon; i++)
        if (!isalnum((unsigned char)uri[i]) && !strchr("+-.", uri[i])) return false;
    return true;
}

bool climbs_out(const std::string &path)
{
    size_t start = 0;
    while (start <= path.size()) {
        size_t end = path.find('/', start);
        if (end == std::string::npos) end = path.size();
        if (path.compare(start, end - start, "..") == 0 && end - start == 2) return true;
        start = end + 1;
    }
    return false;
}

std::string base64(const std::vector<unsigned char> &in)
{
    static const char *tab = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    std::string out;
    out.reserve((in.size() + 2) / 3 * 4);
    size_t i = 0;
    for (; i + 2 < in.size(); i += 3) {
        unsigned v = unsigned(in[i]) << 16 | unsigned(in[i + 1]) << 8 | in[i + 2];
        out += tab[v >> 18];
        out += tab[(v >> 12) & 63];
        out += tab[(v >> 6) & 63];
        out += tab[v & 63];
    }
    if (i + 1 == in.size()) {
        unsigned v = unsigned(in[i]) << 16;
        out += tab[v >> 18];
        out += tab[(v >> 12) & 63];
        out += "==";
    } else if (i + 2 == in.size()) {
        unsigned v = unsigned(in[i]) << 16 | unsigned(in[i + 1]) << 8;
        out += tab[v >> 18];
        out += tab[(v >> 12) & 63];
        out += tab[(v >> 6) & 63];
        out += '=';
    }
    return out;
}

/* ---- tinygltf callbacks ---- */

/* Images are not decoded; a data: URI (which tinygltf does not keep) is
 * rebuilt from the decoded bytes so the writer can emit it again. */
bool keep_image(tinygltf::Image *image, const int, std::string *, std::string *, int, int,
                const unsigned char *bytes, int size, void *)
{
    if (image->uri.empty() && image->bufferView < 0 && bytes && size > 0) {
        std::string mime = image->mimeType.empty() ? "application/octet-stream" : image->mimeType;
        image->uri = "data:" + mime + ";base64," + base64(std::vector<unsigned char>(bytes, bytes + size));
    }
    return true;
}

/* The uri stays exactly as set in the model (tinygltf would keep only the base name). */
bool keep_image_uri(const std::string *, const std::string *, const tinygltf::Image *image, bool,
                    std::string *out_uri, void *)
{
    *out_uri = image->uri;
    return true;
}

/* ---- the writer ---- */

struct PendingFile {
    std::string tmp;       /* inside the private directory */
    std::string final;     /* where it goes */
};

class Writer {
public:
    Writer(const dr_scene *scene, const dr_param_set *params, const char *out)
        : scene_(scene), params_(params), out_(out) {}
    ~Writer() { cleanup(); }
    void run();

private:
    [[noreturn]] DR_PRINTF(3, 4) void fail(int code, const char *fmt, ...);
    void plan_names();
    void load_source();
    void make_temp_dir();
    void remember_draco_indices(const std::string &json_text);
    void apply_params();
    void record_light_units();
    void apply_material(int m, const std::vector<const dr_param *> &ps);
    void apply_light(int l, const std::vector<const dr_param *> &ps);
    void apply_environment(const std::vector<const dr_param *> &ps);
    void write_image_param(const dr_param *p);
    void write_env_map(const dr_param *p, tinygltf::Value::Object &env);
    /* participating media (the "media" section) */
    tinygltf::Value *medium_extension(int medium, std::string *where);
    void apply_medium(const dr_param *p);
    void copy_medium_grids();
    void copy_resources();
    void embed_images();
    std::string copy_one(const std::string &rel, const std::string &what, const std::string &flat_name);
    void set_buffer_uris();
    void declare_extensions();
    void retarget_fitted_textures();
    void write_model();
    void fix_json();
    void check_outputs();
    void commit();
    void cleanup();

    std::vector<double> values(const dr_param *p);
    double clamped(double v, double lo, double hi, const dr_param *p, bool *warned);
    bool image_as_colour(int image) const;
    void claim(const std::string &final_rel, const std::string &what);

    const dr_scene *scene_;
    const dr_param_set *params_;
    std::string out_;

    bool glb_ = false;
    struct DracoIndices { size_t mesh, primitive; long long accessor; };
    std::vector<DracoIndices> draco_indices_;   /* put back by fix_json */
    std::string src_dir_, out_dir_, out_base_, stem_;
    bool same_dir_ = false;
    tinygltf::Model model_;
    std::string tmpdir_;                     /* "" until created; ends with '/' */
    std::vector<PendingFile> files_;         /* written into tmpdir_, renamed by commit() */
    std::map<std::string, std::string> claimed_;   /* final name (relative to out_dir_) -> what */
    std::set<int> replaced_images_;
    bool env_replaced_ = false;
    int copies_ = 0;

    /* commit() state, for rolling back */
    std::vector<std::string> committed_, created_dirs_;
    bool done_ = false;
};

void Writer::fail(int code, const char *fmt, ...)
{
    char buf[2048];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(buf, sizeof buf, fmt, ap);
    va_end(ap);
    dr_set_error("%s: %s", out_.c_str(), buf);
    throw Failure{code};
}

void Writer::claim(const std::string &final_rel, const std::string &what)
{
    auto it = claimed_.find(final_rel);
    if (it != claimed_.end())
        fail(DR_ERR_ARG, "%s and %s would both be written to '%s'", it->second.c_str(), what.c_str(),
             final_rel.c_str());
    claimed_[final_rel] = what;
}

void Writer::plan_names()
{
    if (has_suffix_ci(out_, ".glb")) glb_ = true;
    else if (!has_suffix_ci(out_, ".gltf"))
        fail(DR_ERR_ARG, "the output must be a .gltf or .glb file");
    out_dir_ = directory_of(out_);
    out_base_ = base_of(out_);
    stem_ = out_base_.substr(0, out_base_.size() - (glb_ ? 4 : 5));
    if (stem_.empty()) fail(DR_ERR_ARG, "the output file name has no stem");
    src_dir_ = directory_of(scene_->path);
    struct stat a, b;
    std::string sd = src_dir_.empty() ? "." : src_dir_, od = out_dir_.empty() ? "." : out_dir_;
    same_dir_ = stat(sd.c_str(), &a) == 0 && stat(od.c_str(), &b) == 0 && a.st_dev == b.st_dev && a.st_ino == b.st_ino;
    claim(out_base_, "the output");
}

std::vector<unsigned char> read_all(const std::string &path, int *err);

/* The last error's message with the temporary path tmp named as the file
 * the user will see (final). */
std::string error_naming(const std::string &tmp, const std::string &final_path)
{
    std::string msg = dr_last_error();
    for (size_t at; (at = msg.find(tmp)) != std::string::npos;)
        msg.replace(at, tmp.size(), final_path);
    return msg;
}

std::string glb_json(const std::vector<unsigned char> &glb);

void Writer::load_source()
{
    const char *path = scene_->path;
    FILE *f = fopen(path, "rb");
    if (!f) {
        dr_set_error("%s: cannot open: %s", path, strerror(errno));
        throw Failure{DR_ERR_IO};
    }
    unsigned char magic[4] = {0, 0, 0, 0};
    size_t got = fread(magic, 1, 4, f);
    fclose(f);
    bool binary = (got == 4 && memcmp(magic, "glTF", 4) == 0) || has_suffix_ci(path, ".glb");
    tinygltf::TinyGLTF gltf;
    gltf.SetImageLoader(keep_image, nullptr);
    std::string err, warn;
    bool ok;
    int e = 0;
    std::vector<unsigned char> bytes = read_all(path, &e);
    std::string text = binary ? glb_json(bytes) : std::string(bytes.begin(), bytes.end());
    remember_draco_indices(text);
    /* tinygltf needs Draco's indices stripped (draco_decode.h; fix_json puts
     * them back) and meshopt's fallback buffers marked (meshopt_decode.h) */
    std::vector<unsigned char> glb = bytes;
    bool rewritten = false;
    ok = true;
    if (!draco_indices_.empty()) {
        rewritten = true;
        if (binary) {
            glb = dr_glb_strip_draco_indices(bytes);
            ok = !glb.empty();
        } else {
            dr_draco_strip_indices(text);
        }
    }
    if (binary) {
        std::vector<unsigned char> m = dr_glb_meshopt_mark_fallbacks(glb);
        if (!m.empty()) glb.swap(m), rewritten = true;
    } else {
        rewritten |= dr_meshopt_mark_fallbacks(text);
    }
    if (ok && rewritten)
        ok = binary ? gltf.LoadBinaryFromMemory(&model_, &err, &warn, glb.data(), unsigned(glb.size()), src_dir_)
                    : gltf.LoadASCIIFromString(&model_, &err, &warn, text.data(), unsigned(text.size()), src_dir_);
    else if (ok)
        ok = binary ? gltf.LoadBinaryFromFile(&model_, &err, &warn, path)
                    : gltf.LoadASCIIFromFile(&model_, &err, &warn, path);
    /* meshopt-compressed views are written back decoded, without the extension */
    const bool meshopt = ok && std::find(model_.extensionsUsed.begin(), model_.extensionsUsed.end(),
                                         "EXT_meshopt_compression") != model_.extensionsUsed.end();
    if (meshopt) {
        const std::string why = dr_meshopt_decode(model_);
        if (!why.empty()) {
            dr_set_error("%s: cannot re-read the source scene: %s", path, why.c_str());
            throw Failure{DR_ERR_FORMAT};
        }
        dr_meshopt_drop_compressed_buffers(model_);
    }
    if (!ok) {
        while (!err.empty() && (err.back() == '\n' || err.back() == ' ')) err.pop_back();
        for (char &c : err)
            if (c == '\n') c = ';';
        dr_set_error("%s: cannot re-read the source scene: %s", path, err.empty() ? "tinygltf failed" : err.c_str());
        throw Failure{DR_ERR_FORMAT};
    }
}

/* The JSON chunk of a .glb ("" when malformed: tinygltf then says how). */
std::string glb_json(const std::vector<unsigned char> &glb)
{
    if (glb.size() < 20 || memcmp(glb.data(), "glTF", 4) != 0) return "";
    uint32_t len;
    memcpy(&len, glb.data() + 12, 4);
    if (len > glb.size() - 20) return "";
    return std::string(reinterpret_cast<const char *>(glb.data()) + 20, len);
}

/* Which primitives carry KHR_draco_mesh_compression and which "indices"
 * accessor they name, so the output keeps them (tinygltf reads the source
 * without them). */
void Writer::remember_draco_indices(const std::string &json_text)
{
    draco_indices_.clear();
    if (json_text.find("KHR_draco_mesh_compression") == std::string::npos) return;
    DrJsonDocument doc(nlohmann::json::parse(json_text, nullptr, /*allow_exceptions=*/false));
    nlohmann::json &j = doc.j;
    if (j.is_discarded() || !j.is_object() || !j.contains("meshes") || !j["meshes"].is_array()) return;
    for (size_t m = 0; m < j["meshes"].size(); m++) {
        const nlohmann::json &mesh = j["meshes"][m];
        if (!mesh.is_object() || !mesh.contains("primitives") || !mesh["primitives"].is_array()) continue;
        for (size_t k = 0; k < mesh["primitives"].size(); k++) {
            const nlohmann::json &p = mesh["primitives"][k];
            if (p.is_object() && p.contains("indices") && p["indices"].is_number_integer() && p.contains("extensions") &&
                p["extensions"].is_object() && p["extensions"].contains("KHR_draco_mesh_compression"))
                draco_indices_.push_back({m, k, p["indices"].get<long long>()});
        }
    }
}

void Writer::make_temp_dir()
{
    std::string templ = join(out_dir_, "." + out_base_ + ".tmpXXXXXX");
    std::vector<char> buf(templ.begin(), templ.end());
    buf.push_back('\0');
    if (!mkdtemp(buf.data())) {
        int e = errno;
        std::string od = out_dir_.empty() ? "." : out_dir_;
        fail(DR_ERR_IO, "cannot write: cannot create a temporary directory in %s: %s", od.c_str(), strerror(e));
    }
    tmpdir_ = std::string(buf.data()) + "/";
}

std::vector<double> Writer::values(const dr_param *p)
{
    std::vector<double> v(size_t(p->size > 0 ? p->size : 0));
    if (!v.empty()) dr_param_get(scene_, p, v.data());
    if (!dr_param_is_array(p))
        for (double x : v)
            if (!std::isfinite(x)) fail(DR_ERR_ARG, "%s: the value is not finite (%g)", p->name, x);
    return v;
}

double Writer::clamped(double v, double lo, double hi, const dr_param *p, bool *warned)
{
    double c = v < lo ? lo : v > hi ? hi : v;
    if (c != v && !*warned) {
        dr_warn("%s: %s: value %g is outside glTF's range [%g, %g]; written as %g", out_.c_str(), p->name, v, lo, hi, c);
        *warned = true;
    }
    return c;
}

bool Writer::image_as_colour(int image) const
{
    for (int i = 0; i < scene_->n_materials; i++) {
        const dr_material &m = scene_->materials[i];
        for (const dr_texref *t : {&m.base_color_tex, &m.emissive_tex})
            if (t->texture >= 0 && t->texture < scene_->n_textures && scene_->textures[t->texture].image == image)
                return true;
    }
    return false;
}

double ext_number(const tinygltf::Value &obj, const char *key, double def)
{
    if (!obj.IsObject() || !obj.Has(key) || !obj.Get(key).IsNumber()) return def;
    return obj.Get(key).GetNumberAsDouble();
}

void Writer::apply_material(int mi, const std::vector<const dr_param *> &ps)
{
    if (mi < 0 || size_t(mi) >= model_.materials.size())
        fail(DR_ERR_ARG, "/materials/%d: the source file has no such material", mi);
    tinygltf::Material &m = model_.materials[size_t(mi)];
    tinygltf::PbrMetallicRoughness &pbr = m.pbrMetallicRoughness;
    const dr_param *factor_p = nullptr, *strength_p = nullptr;
    for (const dr_param *p : ps) {
        bool warned = false;
        switch (p->kind) {
        case DR_PARAM_BASE_COLOR: {
            std::vector<double> v = values(p);
            double alpha = pbr.baseColorFactor.size() >= 4 ? pbr.baseColorFactor[3] : 1.0;
            pbr.baseColorFactor = {clamped(v[0], 0, 1, p, &warned), clamped(v[1], 0, 1, p, &warned),
                                   clamped(v[2], 0, 1, p, &warned), alpha};
            break;
        }
        case DR_PARAM_METALLIC: pbr.metallicFactor = clamped(values(p)[0], 0, 1, p, &warned); break;
        case DR_PARAM_ROUGHNESS: pbr.roughnessFactor = clamped(values(p)[0], 0, 1, p, &warned); break;
        case DR_PARAM_EMISSIVE_FACTOR: factor_p = p; break;
        case DR_PARAM_EMISSIVE_STRENGTH: strength_p = p; break;
        case DR_PARAM_CLEARCOAT:
        case DR_PARAM_CLEARCOAT_ROUGHNESS: {
            /* (a parameter of coated materials only, whose extension object exists) */
            tinygltf::Value &ext = m.extensions["KHR_materials_clearcoat"];
            tinygltf::Value::Object o = ext.IsObject() ? ext.Get<tinygltf::Value::Object>() : tinygltf::Value::Object();
            o[p->kind == DR_PARAM_CLEARCOAT ? "clearcoatFactor" : "clearcoatRoughnessFactor"] =
                tinygltf::Value(clamped(values(p)[0], 0, 1, p, &warned));
            ext = tinygltf::Value(std::move(o));
            break;
        }
        case DR_PARAM_ANISOTROPY_STRENGTH: {   /* (anisotropic materials only: the object exists) */
            tinygltf::Value &ext = m.extensions["KHR_materials_anisotropy"];
            tinygltf::Value::Object o = ext.IsObject() ? ext.Get<tinygltf::Value::Object>() : tinygltf::Value::Object();
            o["anisotropyStrength"] = tinygltf::Value(clamped(values(p)[0], 0, 1, p, &warned));
            ext = tinygltf::Value(std::move(o));
            break;
        }
        case DR_PARAM_SHEEN_COLOR:
        case DR_PARAM_SHEEN_ROUGHNESS: {   /* (sheened materials only: the object exists) */
            tinygltf::Value &ext = m.extensions["KHR_materials_sheen"];
            tinygltf::Value::Object o = ext.IsObject() ? ext.Get<tinygltf::Value::Object>() : tinygltf::Value::Object();
            std::vector<double> v = values(p);
            if (p->kind == DR_PARAM_SHEEN_ROUGHNESS) {
                o["sheenRoughnessFactor"] = tinygltf::Value(clamped(v[0], 0, 1, p, &warned));
            } else {
                tinygltf::Value::Array a;
                for (int c = 0; c < 3; c++) a.push_back(tinygltf::Value(clamped(v[size_t(c)], 0, 1, p, &warned)));
                o["sheenColorFactor"] = tinygltf::Value(std::move(a));
            }
            ext = tinygltf::Value(std::move(o));
            break;
        }
        default: break;
        }
    }
    if (!factor_p && !strength_p) return;

    const char *ext_name = "KHR_materials_emissive_strength";
    auto it = m.extensions.find(ext_name);
    bool had_ext = it != m.extensions.end();
    double strength = had_ext ? ext_number(it->second, "emissiveStrength", 1.0) : 1.0;
    bool write_strength = false;
    if (strength_p) {
        bool warned = false;
        strength = clamped(values(strength_p)[0], 0, HUGE_VAL, strength_p, &warned);
        write_strength = true;
    }
    if (factor_p) {
        bool warned = false;
        std::vector<double> f = values(factor_p);
        for (double &x : f) x = clamped(x, 0, HUGE_VAL, factor_p, &warned);
        double mx = std::max(f[0], std::max(f[1], f[2]));
        if (mx > 1.0) {   /* glTF: emissiveFactor components in [0,1]; the excess goes to the strength */
            for (double &x : f) x = std::min(x / mx, 1.0);
            strength *= mx;
            write_strength = true;
        }
        m.emissiveFactor = {f[0], f[1], f[2]};
    }
    if (write_strength) {
        tinygltf::Value::Object obj;
        if (had_ext && it->second.IsObject()) obj = it->second.Get<tinygltf::Value::Object>();
        obj["emissiveStrength"] = tinygltf::Value(strength);
        m.extensions[ext_name] = tinygltf::Value(std::move(obj));
    }
}

void Writer::apply_light(int li, const std::vector<const dr_param *> &ps)
{
    if (li < 0 || size_t(li) >= model_.lights.size())
        fail(DR_ERR_ARG, "/extensions/KHR_lights_punctual/lights/%d: the source file has no such light", li);
    tinygltf::Light &l = model_.lights[size_t(li)];
    const dr_param *color_p = nullptr, *intensity_p = nullptr;
    for (const dr_param *p : ps)
        (p->kind == DR_PARAM_LIGHT_COLOR ? color_p : intensity_p) = p;
    if (intensity_p) {
        bool warned = false;
        l.intensity = clamped(values(intensity_p)[0], 0, HUGE_VAL, intensity_p, &warned);
    }
    if (color_p) {
        bool warned = false;
        std::vector<double> c = values(color_p);
        for (double &x : c) x = clamped(x, 0, HUGE_VAL, color_p, &warned);
        double mx = std::max(c[0], std::max(c[1], c[2]));
        if (mx > 1.0) {   /* KHR_lights_punctual: color components in [0,1] */
            for (double &x : c) x = std::min(x / mx, 1.0);
            l.intensity *= mx;
        }
        l.color = {c[0], c[1], c[2]};
    }
}

void Writer::write_image_param(const dr_param *p)
{
    int n = p->target;
    if (n < 0 || size_t(n) >= model_.images.size())
        fail(DR_ERR_ARG, "/images/%d: the source file has no such image", n);
    std::string name = stem_ + strf(".image%d.png", n);
    claim(name, strf("/images/%d", n));
    std::vector<double> v = values(p);
    std::vector<float> px(v.begin(), v.end());
    std::string tmp = tmpdir_ + name;
    bool srgb = image_as_colour(n) && dr_image_has_linear(&scene_->images[n]);
    if (dr_image_write_encoded(tmp.c_str(), p->width, p->height, p->channels, px.data(), srgb) != 0)
        fail(DR_ERR_IO, "/images/%d: %s", n, error_naming(tmp, join(out_dir_, name)).c_str());
    files_.push_back({tmp, join(out_dir_, name)});
    tinygltf::Image &im = model_.images[size_t(n)];
    im.uri = percent_encode(name);
    im.mimeType.clear();
    im.bufferView = -1;
    replaced_images_.insert(n);
}

void Writer::write_env_map(const dr_param *p, tinygltf::Value::Object &env)
{
    std::string name = stem_ + ".environment.exr";
    claim(name, "/extensions/DR_environment/uri");
    std::vector<double> v = values(p);
    std::vector<float> px(v.begin(), v.end());
    std::string tmp = tmpdir_ + name;
    if (dr_image_write_encoded(tmp.c_str(), p->width, p->height, p->channels, px.data(), false) != 0)
        fail(DR_ERR_IO, "/extensions/DR_environment/uri: %s", error_naming(tmp, join(out_dir_, name)).c_str());
    files_.push_back({tmp, join(out_dir_, name)});
    /* drender reads DR_environment/uri as a plain relative path (no percent-decoding) */
    env["uri"] = tinygltf::Value(name);
    env_replaced_ = true;
}

void Writer::apply_environment(const std::vector<const dr_param *> &ps)
{
    auto it = model_.extensions.find("DR_environment");
    tinygltf::Value::Object env;
    if (it != model_.extensions.end() && it->second.IsObject()) env = it->second.Get<tinygltf::Value::Object>();
    for (const dr_param *p : ps) {
        if (p->kind == DR_PARAM_ENV_COLOR) {
            std::vector<double> c = values(p);
            env["color"] = tinygltf::Value(tinygltf::Value::Array{tinygltf::Value(c[0]), tinygltf::Value(c[1]),
                                                                  tinygltf::Value(c[2])});
        } else if (p->kind == DR_PARAM_ENV_STRENGTH) {
            env["strength"] = tinygltf::Value(values(p)[0]);
        } else if (p->kind == DR_PARAM_ENV_MAP) {
            write_env_map(p, env);
        }
    }
    model_.extensions["DR_environment"] = tinygltf::Value(std::move(env));
}

/* ---- participating media ---- */

bool copyable(const std::string &uri);

/* The DR_medium object of a medium (created if the source has none: a
 * KHR_materials_volume medium gets DR_medium values that override it). */
tinygltf::Value *Writer::medium_extension(int medium, std::string *where)
{
    int mat = scene_->media[medium].material;
    tinygltf::ExtensionMap *ext = &model_.extensions;
    *where = "/extensions/DR_medium";
    if (mat >= 0) {
        if (size_t(mat) >= model_.materials.size())
            fail(DR_ERR_ARG, "/materials/%d: the source file has no such material", mat);
        ext = &model_.materials[size_t(mat)].extensions;
        *where = strf("/materials/%d/extensions/DR_medium", mat);
    }
    tinygltf::Value &v = (*ext)["DR_medium"];
    if (!v.IsObject()) v = tinygltf::Value(tinygltf::Value::Object());
    return &v;
}

void Writer::apply_medium(const dr_param *p)
{
    std::string where;
    tinygltf::Value *v = medium_extension(p->target, &where);
    tinygltf::Value::Object obj = v->Get<tinygltf::Value::Object>();
    std::vector<double> x = values(p);
    switch (p->kind) {
    case DR_PARAM_MEDIUM_EXTINCTION:
    case DR_PARAM_MEDIUM_ALBEDO:
    {
        tinygltf::Value::Array c;
        for (int k = 0; k < 3; k++) c.push_back(tinygltf::Value(x[size_t(k)]));
        obj[p->kind == DR_PARAM_MEDIUM_ALBEDO ? "albedo" : "extinction"] = tinygltf::Value(std::move(c));
    }
        break;
    case DR_PARAM_MEDIUM_G: obj["g"] = tinygltf::Value(x[0]); break;
    case DR_PARAM_MEDIUM_DENSITY_SCALE: obj["density_scale"] = tinygltf::Value(x[0]); break;
    default: {
        /* the grid as raw float32 next to the output, with its resolution */
        const dr_grid &g = scene_->media[p->target].grid;
        std::string name = stem_ + strf(".medium%d.raw", p->target);
        claim(name, where + "/density/uri");
        std::string tmp = tmpdir_ + name;
        FILE *f = fopen(tmp.c_str(), "wb");
        bool ok = f && fwrite(g.density, sizeof(float), size_t(p->size), f) == size_t(p->size);
        int e = errno;
        if (f && fclose(f) != 0 && ok) ok = false, e = errno;
        if (!ok)
            fail(DR_ERR_IO, "%s/density/uri: cannot write %s: %s", where.c_str(), join(out_dir_, name).c_str(),
                 strerror(e));
        files_.push_back({tmp, join(out_dir_, name)});
        tinygltf::Value::Array res;
        for (int n : {g.nx, g.ny, g.nz}) res.push_back(tinygltf::Value(n));
        tinygltf::Value::Object dens;
        dens["uri"] = tinygltf::Value(name);
        dens["resolution"] = tinygltf::Value(std::move(res));
        obj["density"] = tinygltf::Value(std::move(dens));
        break;
    }
    }
    *v = tinygltf::Value(std::move(obj));
}

/* Density grids the output still references from the source: copied. */
void Writer::copy_medium_grids()
{
    for (int i = 0; i < scene_->n_media; i++) {
        std::string where;
        int mat = scene_->media[i].material;
        const tinygltf::ExtensionMap &ext = mat >= 0 && size_t(mat) < model_.materials.size()
                                                ? model_.materials[size_t(mat)].extensions : model_.extensions;
        auto it = ext.find("DR_medium");
        if (it == ext.end() || !it->second.IsObject() || !it->second.Has("density")) continue;
        const tinygltf::Value &d = it->second.Get("density");
        if (!d.IsObject() || !d.Has("uri") || !d.Get("uri").IsString()) continue;
        std::string rel = d.Get("uri").Get<std::string>();
        if (rel.rfind(stem_ + ".medium", 0) == 0 || !copyable(rel)) continue;   /* written by apply_medium */
        tinygltf::Value *v = medium_extension(i, &where);
        std::string final_rel = copy_one(rel, where + "/density/uri", stem_ + strf(".medium%d", i));
        if (final_rel != rel) {
            tinygltf::Value::Object obj = v->Get<tinygltf::Value::Object>();
            tinygltf::Value::Object dens = obj["density"].Get<tinygltf::Value::Object>();
            dens["uri"] = tinygltf::Value(final_rel);
            obj["density"] = tinygltf::Value(std::move(dens));
            *v = tinygltf::Value(std::move(obj));
        }
    }
}

void Writer::apply_params()
{
    if (!params_) return;
    std::map<int, std::vector<const dr_param *>> mats, lights;
    std::vector<const dr_param *> env;
    for (int i = 0; i < params_->n; i++) {
        const dr_param *p = &params_->params[i];
        switch (p->kind) {
        case DR_PARAM_BASE_COLOR:
        case DR_PARAM_METALLIC:
        case DR_PARAM_ROUGHNESS:
        case DR_PARAM_EMISSIVE_FACTOR:
        case DR_PARAM_EMISSIVE_STRENGTH:
        case DR_PARAM_CLEARCOAT:
        case DR_PARAM_CLEARCOAT_ROUGHNESS:
        case DR_PARAM_ANISOTROPY_STRENGTH:
        case DR_PARAM_SHEEN_COLOR:
        case DR_PARAM_SHEEN_ROUGHNESS: mats[p->target].push_back(p); break;
        case DR_PARAM_LIGHT_COLOR:
        case DR_PARAM_LIGHT_INTENSITY: lights[p->target].push_back(p); break;
        case DR_PARAM_ENV_COLOR:
        case DR_PARAM_ENV_STRENGTH:
        case DR_PARAM_ENV_MAP: env.push_back(p); break;
        case DR_PARAM_IMAGE: write_image_param(p); break;
        case DR_PARAM_MEDIUM_EXTINCTION:
        case DR_PARAM_MEDIUM_ALBEDO:
        case DR_PARAM_MEDIUM_G:
        case DR_PARAM_MEDIUM_DENSITY_SCALE:
        case DR_PARAM_MEDIUM_DENSITY: apply_medium(p); break;
        default: fail(DR_ERR_ARG, "%s: this kind of parameter cannot be written", p->name);
        }
    }
    for (auto &kv : mats) apply_material(kv.first, kv.second);
    for (auto &kv : lights) apply_light(kv.first, kv.second);
    if (!env.empty()) apply_environment(env);
}

/* The intensities are written back as they were read (in the scene's units);
 * when those are not glTF's photometric ones, DR_units says so, so that the
 * output reads back the same, also after --light-units changed them. */
void Writer::record_light_units()
{
    bool radiometric = scene_->light_units == DR_LIGHT_UNITS_RADIOMETRIC;
    auto it = model_.extensions.find("DR_units");
    if (model_.lights.empty() || (!radiometric && it == model_.extensions.end())) return;
    tinygltf::Value::Object units;
    if (it != model_.extensions.end() && it->second.IsObject()) units = it->second.Get<tinygltf::Value::Object>();
    units["lights"] = tinygltf::Value(std::string(radiometric ? "radiometric" : "photometric"));
    model_.extensions["DR_units"] = tinygltf::Value(std::move(units));
}

/* One external file the output references (rel: a path relative to the source
 * directory, not percent-encoded), copied next to the output. Returns the path
 * it gets relative to the output directory: rel itself, or flat_name + its
 * extension when rel climbs out with "..". */
std::string Writer::copy_one(const std::string &rel, const std::string &what, const std::string &flat_name)
{
    std::string src = join(src_dir_, rel);
    std::string final_rel = rel;
    if (climbs_out(rel)) {   /* it would land outside the output directory: rename it */
        std::string base = base_of(rel), ext;
        size_t dot = base.find_last_of('.');
        if (dot != std::string::npos) ext = base.substr(dot);
        final_rel = flat_name + ext;
    }
    std::string who = "a copy of " + src;
    auto it = claimed_.find(final_rel);
    if (it != claimed_.end() && it->second == who) return final_rel;   /* shared by several images */
    claim(final_rel, who);

    FILE *in = fopen(src.c_str(), "rb");
    if (!in) {
        int e = errno;
        fail(DR_ERR_IO, "%s: cannot copy '%s': %s", what.c_str(), src.c_str(), strerror(e));
    }
    std::string tmp = tmpdir_ + strf("copy%d", copies_++);
    FILE *out = fopen(tmp.c_str(), "wb");
    if (!out) {
        int e = errno;
        fclose(in);
        fail(DR_ERR_IO, "cannot write a temporary file in %s: %s", tmpdir_.c_str(), strerror(e));
    }
    files_.push_back({tmp, join(out_dir_, final_rel)});
    char buf[65536];
    size_t n;
    bool ok = true;
    while ((n = fread(buf, 1, sizeof buf, in)) > 0)
        if (fwrite(buf, 1, n, out) != n) {
            ok = false;
            break;
        }
    int e = errno;
    bool rerr = ferror(in);
    fclose(in);
    if (fclose(out) != 0 && ok) {
        ok = false;
        e = errno;
    }
    if (rerr) fail(DR_ERR_IO, "%s: cannot read '%s': %s", what.c_str(), src.c_str(), strerror(e));
    if (!ok) fail(DR_ERR_IO, "%s: cannot copy '%s': %s", what.c_str(), src.c_str(), strerror(e));
    return final_rel;
}

/* Files referenced by a relative path; absolute paths and URIs with a scheme
 * (http:, file:, data:) resolve the same from anywhere. */
bool copyable(const std::string &uri) { return !uri.empty() && uri[0] != '/' && !has_scheme(uri); }

void Writer::copy_resources()
{
    if (same_dir_) return;
    copy_medium_grids();
    for (size_t i = 0; i < model_.images.size(); i++) {
        tinygltf::Image &im = model_.images[i];
        if (replaced_images_.count(int(i)) || im.bufferView >= 0 || !copyable(im.uri)) continue;
        std::string rel = percent_decode(im.uri);
        std::string final_rel = copy_one(rel, strf("/images/%zu/uri", i), stem_ + strf(".image%zu", i));
        if (final_rel != rel) im.uri = percent_encode(final_rel);
    }
    auto it = model_.extensions.find("DR_environment");
    if (env_replaced_ || it == model_.extensions.end() || !it->second.IsObject() || !it->second.Has("uri") ||
        !it->second.Get("uri").IsString())
        return;
    /* drender reads DR_environment/uri as a plain path (not percent-encoded) */
    std::string rel = it->second.Get("uri").Get<std::string>();
    if (!copyable(rel)) return;
    std::string final_rel = copy_one(rel, "/extensions/DR_environment/uri", stem_ + ".environment");
    if (final_rel != rel) {
        tinygltf::Value::Object env = it->second.Get<tinygltf::Value::Object>();
        env["uri"] = tinygltf::Value(final_rel);
        it->second = tinygltf::Value(std::move(env));
    }
}

/* A .glb is one file: every image it references by a relative path (the
 * source's files, or a texture parameter just written) moves into the binary
 * chunk as a bufferView, so the output is self-contained. Only PNG and JPEG
 * may be embedded (glTF's mimeTypes); anything else stays beside the file. */
void Writer::embed_images()
{
    if (model_.buffers.empty()) model_.buffers.emplace_back();
    std::vector<unsigned char> &bin = model_.buffers[0].data;
    for (size_t i = 0; i < model_.images.size(); i++) {
        tinygltf::Image &im = model_.images[i];
        if (im.bufferView >= 0 || !copyable(im.uri)) continue;
        std::string rel = percent_decode(im.uri);
        std::string mime = has_suffix_ci(rel, ".png") ? "image/png"
                           : has_suffix_ci(rel, ".jpg") || has_suffix_ci(rel, ".jpeg") ? "image/jpeg" : "";
        if (mime.empty()) continue;
        std::string src = join(src_dir_, rel);
        bool written_now = replaced_images_.count(int(i)) > 0;
        if (written_now) {   /* the parameter's PNG in the private directory: embed it instead of placing it */
            src = tmpdir_ + rel;
            files_.erase(std::remove_if(files_.begin(), files_.end(), [&](const PendingFile &f) { return f.tmp == src; }),
                         files_.end());
        }
        int e = 0;
        std::vector<unsigned char> bytes = read_all(src, &e);
        if (e) fail(DR_ERR_IO, "/images/%zu/uri: cannot read %s to embed it: %s", i, src.c_str(), strerror(e));
        if (bytes.empty()) fail(DR_ERR_IO, "/images/%zu/uri: %s is empty", i, src.c_str());
        if (written_now) remove(src.c_str());
        while (bin.size() % 4) bin.push_back(0);
        tinygltf::BufferView view;
        view.buffer = 0;
        view.byteOffset = bin.size();
        view.byteLength = bytes.size();
        bin.insert(bin.end(), bytes.begin(), bytes.end());
        model_.bufferViews.push_back(view);
        im.bufferView = int(model_.bufferViews.size() - 1);
        im.mimeType = mime;
        im.uri.clear();
    }
}

void Writer::set_buffer_uris()
{
    for (size_t i = 0; i < model_.buffers.size(); i++) {
        tinygltf::Buffer &b = model_.buffers[i];
        if (glb_ && i == 0) {
            b.uri.clear();   /* the GLB binary chunk */
            continue;
        }
        std::string name = i == 0 ? stem_ + ".bin" : stem_ + strf(".%zu.bin", i);
        claim(name, strf("/buffers/%zu", i));
        b.uri = percent_encode(name);
        /* tinygltf writes the file under the uri as given (not decoded) */
        files_.push_back({tmpdir_ + b.uri, join(out_dir_, name)});
    }
}

/* A fitted image is written as PNG (write_image_param). A texture that
 * reached it through KHR_texture_basisu or EXT_texture_webp would then name
 * a PNG where the extension requires KTX2 or WebP, and one that kept such an
 * image beside a fitted `source` fallback would show viewers that decode it
 * the unfitted texels. Such a texture takes the fitted image as its `source`
 * and drops the extension; an extension no texture uses any more leaves
 * extensionsUsed and extensionsRequired (declare_extensions only adds). The
 * KTX2 or WebP image stays in the file, unused. */
void Writer::retarget_fitted_textures()
{
    for (const char *ext : {"KHR_texture_basisu", "EXT_texture_webp"}) {
        bool present = false, still_used = false;
        for (tinygltf::Texture &t : model_.textures) {
            auto it = t.extensions.find(ext);
            if (it == t.extensions.end()) continue;
            present = true;
            const tinygltf::Value &src = it->second.Get("source");
            const int used = t.source >= 0 ? t.source : src.IsInt() ? src.GetNumberAsInt() : -1;
            if (used >= 0 && replaced_images_.count(used)) {
                t.source = used;
                t.extensions.erase(it);
            } else {
                still_used = true;
            }
        }
        if (!present || still_used) continue;
        for (std::vector<std::string> *list : {&model_.extensionsUsed, &model_.extensionsRequired})
            list->erase(std::remove(list->begin(), list->end(), std::string(ext)), list->end());
    }
}

/* extensionsUsed must name every extension the file uses (the validator's
 * UNDECLARED_EXTENSION error); the loader is lenient, the output is not. */
void Writer::declare_extensions()
{
    std::set<std::string> used;
    auto add = [&](const tinygltf::ExtensionMap &e) {
        for (const auto &kv : e) used.insert(kv.first);
    };
    auto add_ti = [&](const tinygltf::TextureInfo &t) {
        if (t.index >= 0) add(t.extensions);
    };
    add(model_.extensions);
    if (!model_.lights.empty()) used.insert("KHR_lights_punctual");
    for (const auto &m : model_.materials) {
        add(m.extensions);
        add(m.pbrMetallicRoughness.extensions);
        add_ti(m.pbrMetallicRoughness.baseColorTexture);
        add_ti(m.pbrMetallicRoughness.metallicRoughnessTexture);
        add_ti(m.emissiveTexture);
        if (m.normalTexture.index >= 0) add(m.normalTexture.extensions);
        if (m.occlusionTexture.index >= 0) add(m.occlusionTexture.extensions);
    }
    for (const auto &x : model_.nodes) add(x.extensions);
    for (const auto &x : model_.meshes) {
        add(x.extensions);
        for (const auto &p : x.primitives) add(p.extensions);
    }
    for (const auto &x : model_.textures) add(x.extensions);
    for (const auto &x : model_.images) add(x.extensions);
    for (const auto &x : model_.samplers) add(x.extensions);
    for (const auto &x : model_.cameras) add(x.extensions);
    for (const auto &x : model_.lights) add(x.extensions);
    for (const auto &x : model_.accessors) add(x.extensions);
    for (const auto &x : model_.bufferViews) add(x.extensions);
    for (const auto &x : model_.buffers) add(x.extensions);
    for (const auto &x : model_.scenes) add(x.extensions);
    for (const auto &x : model_.skins) add(x.extensions);
    for (const auto &x : model_.animations) add(x.extensions);
    for (const std::string &name : used)
        if (std::find(model_.extensionsUsed.begin(), model_.extensionsUsed.end(), name) == model_.extensionsUsed.end())
            model_.extensionsUsed.push_back(name);
}

void Writer::write_model()
{
    tinygltf::TinyGLTF gltf;
    gltf.SetImageWriter(keep_image_uri, nullptr);
    std::string tmp = tmpdir_ + out_base_;
    bool ok = gltf.WriteGltfSceneToFile(&model_, tmp, /*embedImages=*/false, /*embedBuffers=*/false,
                                        /*prettyPrint=*/true, /*writeBinary=*/glb_);
    if (!ok) fail(DR_ERR_IO, "cannot write: tinygltf failed to write the file or its buffers");
    files_.push_back({tmp, out_});
}

/* ---- repairing what tinygltf wrote ---- */

/* Why a file tinygltf wrote is cut short: its writes (std::ofstream) report nothing. */
std::string why_cut_short(const std::string &path)
{
    char buf[256];
    return dr_why_cut_short(path.c_str(), buf, sizeof buf);
}

std::vector<unsigned char> read_all(const std::string &path, int *err)
{
    std::vector<unsigned char> out;
    FILE *f = fopen(path.c_str(), "rb");
    if (!f) {
        *err = errno;
        return out;
    }
    unsigned char buf[65536];
    size_t n;
    while ((n = fread(buf, 1, sizeof buf, f)) > 0) out.insert(out.end(), buf, buf + n);
    *err = ferror(f) ? errno : 0;
    fclose(f);
    return out;
}

bool write_all(const std::string &path, const std::string &bytes, int *err)
{
    FILE *f = fopen(path.c_str(), "wb");
    if (!f) {
        *err = errno;
        return false;
    }
    bool ok = fwrite(bytes.data(), 1, bytes.size(), f) == bytes.size();
    *err = errno;
    if (fclose(f) != 0 && ok) {
        ok = false;
        *err = errno;
    }
    return ok;
}

void put_u32(std::string &s, uint32_t v)
{
    for (int i = 0; i < 4; i++) s += char((v >> (8 * i)) & 0xff);
}

uint32_t get_u32(const unsigned char *p) { return uint32_t(p[0]) | uint32_t(p[1]) << 8 | uint32_t(p[2]) << 16 | uint32_t(p[3]) << 24; }

/* What tinygltf 2.7 writes wrongly. */
void repair(nlohmann::json &j)
{
    auto cams = j.find("cameras");
    if (cams != j.end() && cams->is_array())
        for (auto &c : *cams) {
            auto p = c.find("perspective");
            if (p == c.end() || !p->is_object()) continue;
            auto zf = p->find("zfar");   /* absent = infinite; 0 is invalid */
            if (zf != p->end() && zf->is_number() && zf->get<double>() <= 0.0) p->erase(zf);
        }
}

void Writer::fix_json()
{
    std::string path = tmpdir_ + out_base_;
    int e = 0;
    std::vector<unsigned char> bytes = read_all(path, &e);
    if (e) fail(DR_ERR_IO, "cannot write: cannot read back the written file: %s", strerror(e));
    std::string json_text, bin_chunk;
    if (glb_) {
        /* header (12 bytes), JSON chunk, optional BIN chunk, as tinygltf wrote them */
        size_t n = bytes.size();
        bool ok = n >= 20 && memcmp(bytes.data(), "glTF", 4) == 0 && get_u32(&bytes[8]) == n &&
                  get_u32(&bytes[16]) == 0x4E4F534Au && get_u32(&bytes[12]) <= n - 20;
        size_t json_len = ok ? get_u32(&bytes[12]) : 0;
        size_t at = 20 + json_len;
        if (ok) {
            json_text.assign(bytes.begin() + 20, bytes.begin() + long(at));
            if (at < n) {
                ok = n - at >= 8 && get_u32(&bytes[at + 4]) == 0x004E4942u && get_u32(&bytes[at]) <= n - at - 8;
                if (ok) bin_chunk.assign(bytes.begin() + long(at), bytes.begin() + long(at + 8 + get_u32(&bytes[at])));
            }
        }
        if (!ok) fail(DR_ERR_IO, "cannot write: %s", why_cut_short(path).c_str());
    } else {
        json_text.assign(bytes.begin(), bytes.end());
    }
    DrJsonDocument doc(nlohmann::json::parse(json_text, nullptr, /*allow_exceptions=*/false));
    nlohmann::json &j = doc.j;
    if (j.is_discarded() || !j.is_object())
        fail(DR_ERR_IO, "cannot write: %s", why_cut_short(path).c_str());
    repair(j);
    for (const DracoIndices &d : draco_indices_)
        if (j.contains("meshes") && d.mesh < j["meshes"].size() && d.primitive < j["meshes"][d.mesh]["primitives"].size())
            j["meshes"][d.mesh]["primitives"][d.primitive]["indices"] = d.accessor;
    std::string out;
    if (glb_) {
        std::string text = j.dump();
        while (text.size() % 4) text += ' ';
        put_u32(out, 0x46546C67u);   /* "glTF" */
        put_u32(out, 2);
        put_u32(out, uint32_t(12 + 8 + text.size() + bin_chunk.size()));
        put_u32(out, uint32_t(text.size()));
        put_u32(out, 0x4E4F534Au);   /* "JSON" */
        out += text;
        out += bin_chunk;
    } else {
        out = j.dump(2) + "\n";
    }
    if (!write_all(path, out, &e)) fail(DR_ERR_IO, "cannot write: %s", strerror(e));
}

/* tinygltf does not check its writes: verify what is on disk, and sync it. */
void Writer::check_outputs()
{
    auto file_size = [&](const std::string &p) -> long long {
        struct stat st;
        if (stat(p.c_str(), &st) != 0) fail(DR_ERR_IO, "cannot write: '%s' is missing: %s", base_of(p).c_str(), strerror(errno));
        return (long long)st.st_size;
    };
    for (size_t i = 0; i < model_.buffers.size(); i++) {
        if (glb_ && i == 0) continue;
        long long want = (long long)model_.buffers[i].data.size();
        const std::string bin = tmpdir_ + model_.buffers[i].uri;
        long long got = file_size(bin);
        if (got != want)
            fail(DR_ERR_IO, "cannot write /buffers/%zu: %lld of %lld bytes written: %s", i, got, want,
                 why_cut_short(bin).c_str());
    }
    for (const PendingFile &pf : files_) {
        int fd = open(pf.tmp.c_str(), O_RDONLY);
        if (fd < 0 || fsync(fd) != 0) {
            int e = errno;
            if (fd >= 0) close(fd);
            fail(DR_ERR_IO, "cannot write '%s': %s", pf.final.c_str(), strerror(e));
        }
        close(fd);
    }
}

void Writer::commit()
{
    /* subdirectories of copied images (uri "textures/a.png") */
    for (const PendingFile &pf : files_) {
        std::string rel = pf.final.substr(out_dir_.size());
        for (size_t slash = rel.find('/'); slash != std::string::npos; slash = rel.find('/', slash + 1)) {
            std::string d = out_dir_ + rel.substr(0, slash);
            if (mkdir(d.c_str(), 0777) == 0) {
                created_dirs_.push_back(d);
            } else if (errno != EEXIST) {
                int e = errno;
                fail(DR_ERR_IO, "cannot create directory '%s': %s", d.c_str(), strerror(e));
            }
        }
    }
    /* resources first, the .gltf/.glb (the last entry) last */
    for (const PendingFile &pf : files_) {
        if (rename(pf.tmp.c_str(), pf.final.c_str()) != 0) {
            int e = errno;
            fail(DR_ERR_IO, "cannot write '%s': %s", pf.final.c_str(), strerror(e));
        }
        committed_.push_back(pf.final);
    }
    std::string od = out_dir_.empty() ? "." : out_dir_;
    int fd = open(od.c_str(), O_RDONLY | O_DIRECTORY);
    if (fd >= 0) {
        (void)fsync(fd);
        close(fd);
    }
    done_ = true;
}

void Writer::cleanup()
{
    if (!done_) {   /* roll back: nothing of a failed write stays */
        for (const std::string &f : committed_) unlink(f.c_str());
        for (auto it = created_dirs_.rbegin(); it != created_dirs_.rend(); ++it) rmdir(it->c_str());
    }
    if (tmpdir_.empty()) return;
    /* the private directory holds only what we put there */
    if (DIR *d = opendir(tmpdir_.c_str())) {
        std::vector<std::string> names;
        while (struct dirent *e = readdir(d))
            if (strcmp(e->d_name, ".") != 0 && strcmp(e->d_name, "..") != 0) names.push_back(e->d_name);
        closedir(d);
        for (const std::string &n : names) unlink((tmpdir_ + n).c_str());
    }
    rmdir(tmpdir_.c_str());
    tmpdir_.clear();
}

void Writer::run()
{
    if (!scene_->path || !*scene_->path) {
        dr_set_error("%s: cannot write: the scene has no source file", out_.c_str());
        throw Failure{DR_ERR_ARG};
    }
    plan_names();
    load_source();
    make_temp_dir();
    apply_params();
    retarget_fitted_textures();
    record_light_units();
    if (glb_) embed_images();
    copy_resources();
    set_buffer_uris();
    declare_extensions();
    write_model();
    fix_json();
    check_outputs();
    commit();
    cleanup();
}

}  // namespace

extern "C" int dr_gltf_write(const struct dr_scene *scene, const struct dr_param_set *params, const char *out_path)
{
    if (!out_path || !*out_path) {
        dr_set_error("cannot write glTF: empty file name");
        return DR_ERR_ARG;
    }
    if (!scene) {
        dr_set_error("%s: cannot write glTF: no scene", out_path);
        return DR_ERR_ARG;
    }
    try {
        Writer w(scene, params, out_path);
        w.run();
        return 0;
    } catch (const Failure &f) {
        return f.code;
    } catch (const std::bad_alloc &) {
        dr_set_error("%s: out of memory", out_path);
        return DR_ERR_NOMEM;
    } catch (const std::exception &e) {
        dr_set_error("%s: internal error: %s", out_path, e.what());
        return DR_ERR_INTERNAL;
    } catch (...) {
        dr_set_error("%s: internal error", out_path);
        return DR_ERR_INTERNAL;
    }
}
