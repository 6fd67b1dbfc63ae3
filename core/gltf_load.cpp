/* glTF 2.0 (.gltf / .glb) -> struct dr_scene, through tinygltf.
 *
 * The only file that includes tinygltf. tinygltf parses the JSON and reads the
 * buffers; everything it leaves unchecked (indices, byte ranges, node graph)
 * is validated here, because the tracer trusts the arrays it gets. Every error
 * names the scene file and the JSON pointer of the offending value.
 *
 * Internally a failure throws `Failure` after dr_set_error(); the extern "C"
 * entry point catches it (and everything else), so no exception escapes. */
#include <tiny_gltf.h>
#include <nlohmann/json.hpp>   /* the JSON library tinygltf itself is built with */

#include <algorithm>
#include <cerrno>
#include <cstdarg>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cmath>
#include <cstring>
#include <map>
#include <memory>
#include <set>
#include <new>
#include <string>
#include <system_error>
#include <thread>
#include <utility>
#include <vector>

#include <strings.h>

#include "draco_decode.h"
#include "meshopt_decode.h"
#include "error.h"
#include "image_io.h"
#include "ktx2.h"
#include "medium.h"
extern "C" {
#include "parallel.h"   /* dr_parallel_for, dr_default_threads */
}
#include "scene.h"

namespace {

struct Failure {
    int code;
};

#if defined(__GNUC__)
#define DR_PRINTF(a, b) __attribute__((format(printf, a, b)))
#else
#define DR_PRINTF(a, b)
#endif

std::string vstrf(const char *fmt, va_list ap)
{
    char buf[1024];
    vsnprintf(buf, sizeof buf, fmt, ap);
    return buf;
}

DR_PRINTF(1, 2) std::string strf(const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    std::string s = vstrf(fmt, ap);
    va_end(ap);
    return s;
}

void copy_name(char dst[DR_NAME_MAX], const std::string &src)
{
    snprintf(dst, DR_NAME_MAX, "%s", src.c_str());
}

/* Copies a vector into a malloc'd array (the C side frees it); `extra` zeroed
 * elements are appended. Empty -> NULL. */
template <class T> T *copy_out(const std::vector<T> &v, size_t extra = 0)
{
    size_t n = v.size() + extra;
    if (n == 0) return nullptr;
    T *p = static_cast<T *>(calloc(n, sizeof(T)));
    if (!p) throw std::bad_alloc();
    if (!v.empty()) memcpy(p, v.data(), v.size() * sizeof(T));
    return p;
}

/* ---- 4x4 affine matrices, column-major as glTF stores them: m[col*4+row] ---- */

struct Mat4 {
    double m[16];
    double operator()(int row, int col) const { return m[col * 4 + row]; }
};

Mat4 mat_identity()
{
    Mat4 r = {};
    r.m[0] = r.m[5] = r.m[10] = r.m[15] = 1.0;
    return r;
}

Mat4 mat_mul(const Mat4 &a, const Mat4 &b)
{
    Mat4 r;
    for (int c = 0; c < 4; c++)
        for (int row = 0; row < 4; row++) {
            double s = 0.0;
            for (int k = 0; k < 4; k++) s += a(row, k) * b(k, c);
            r.m[c * 4 + row] = s;
        }
    return r;
}

dr_vec3 mat_point(const Mat4 &a, double x, double y, double z)
{
    return dr_v3(a(0, 0) * x + a(0, 1) * y + a(0, 2) * z + a(0, 3),
                 a(1, 0) * x + a(1, 1) * y + a(1, 2) * z + a(1, 3),
                 a(2, 0) * x + a(2, 1) * y + a(2, 2) * z + a(2, 3));
}

dr_vec3 mat_column(const Mat4 &a, int c) { return dr_v3(a(0, c), a(1, c), a(2, c)); }

/* Normals transform with the inverse transpose of the upper 3x3. The cofactor
 * matrix is det * inverse-transpose; times sign(det) it points the right way
 * and needs no division, so singular scales do not produce NaNs. */
struct NormalXform {
    double n[3][3];
    bool mirrored;  /* det < 0: the winding flips */
};

Mat4 trs_matrix(const double t[3], double q[4], const double s[3]);   /* (the node graph's, below) */

NormalXform normal_xform(const Mat4 &a)
{
    auto e = [&](int r, int c) { return a(r, c); };
    double cof[3][3];
    for (int r = 0; r < 3; r++)
        for (int c = 0; c < 3; c++) {
            int r1 = (r + 1) % 3, r2 = (r + 2) % 3, c1 = (c + 1) % 3, c2 = (c + 2) % 3;
            cof[r][c] = e(r1, c1) * e(r2, c2) - e(r1, c2) * e(r2, c1);
        }
    double det = e(0, 0) * cof[0][0] + e(0, 1) * cof[0][1] + e(0, 2) * cof[0][2];
    NormalXform x;
    x.mirrored = det < 0.0;
    double s = x.mirrored ? -1.0 : 1.0;
    for (int r = 0; r < 3; r++)
        for (int c = 0; c < 3; c++) x.n[r][c] = s * cof[r][c];
    return x;
}

/* ---- component types ---- */

size_t component_size(int type)
{
    switch (type) {
    case TINYGLTF_COMPONENT_TYPE_BYTE: case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE: return 1;
    case TINYGLTF_COMPONENT_TYPE_SHORT: case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT: return 2;
    case TINYGLTF_COMPONENT_TYPE_INT: case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT:
    case TINYGLTF_COMPONENT_TYPE_FLOAT: return 4;
    case TINYGLTF_COMPONENT_TYPE_DOUBLE: return 8;
    default: return 0;
    }
}

const char *type_name(int type)
{
    switch (type) {
    case TINYGLTF_TYPE_SCALAR: return "SCALAR";
    case TINYGLTF_TYPE_VEC2: return "VEC2";
    case TINYGLTF_TYPE_VEC3: return "VEC3";
    case TINYGLTF_TYPE_VEC4: return "VEC4";
    case TINYGLTF_TYPE_MAT2: return "MAT2";
    case TINYGLTF_TYPE_MAT3: return "MAT3";
    case TINYGLTF_TYPE_MAT4: return "MAT4";
    default: return "unknown";
    }
}

/* A validated view of an accessor: element i, component c is at
 * base + i*stride + c*component_size. base == NULL: no bufferView, all zeros
 * (as the spec says for accessors without one). Sparse accessors and Draco
 * attributes are materialised into `owned`, which base then points into. */
struct AccessorView {
    const unsigned char *base = nullptr;
    size_t stride = 0, count = 0;
    int comp_type = 0;
    bool normalized = false;
    std::shared_ptr<std::vector<unsigned char>> owned;

    template <class T> T raw(size_t i, int c) const
    {
        T v;
        memcpy(&v, base + i * stride + size_t(c) * sizeof(T), sizeof(T));  /* may be unaligned */
        return v;
    }

    /* As a float, applying the glTF normalised-integer rules when flagged. */
    double get(size_t i, int c) const
    {
        if (!base) return 0.0;
        switch (comp_type) {
        case TINYGLTF_COMPONENT_TYPE_FLOAT: return raw<float>(i, c);
        case TINYGLTF_COMPONENT_TYPE_DOUBLE: return raw<double>(i, c);
        case TINYGLTF_COMPONENT_TYPE_BYTE: {
            double v = raw<int8_t>(i, c);
            return normalized ? fmax(v / 127.0, -1.0) : v;
        }
        case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE: {
            double v = raw<uint8_t>(i, c);
            return normalized ? v / 255.0 : v;
        }
        case TINYGLTF_COMPONENT_TYPE_SHORT: {
            double v = raw<int16_t>(i, c);
            return normalized ? fmax(v / 32767.0, -1.0) : v;
        }
        case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT: {
            double v = raw<uint16_t>(i, c);
            return normalized ? v / 65535.0 : v;
        }
        case TINYGLTF_COMPONENT_TYPE_INT: return raw<int32_t>(i, c);
        case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT: {
            double v = raw<uint32_t>(i, c);
            return normalized ? v / 4294967295.0 : v;
        }
        default: return 0.0;
        }
    }

    uint32_t index(size_t i) const
    {
        if (!base) return 0;
        switch (comp_type) {
        case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE: return raw<uint8_t>(i, 0);
        case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT: return raw<uint16_t>(i, 0);
        default: return raw<uint32_t>(i, 0);
        }
    }
};

const char *const kSupportedExtensions[] = {
    "KHR_materials_emissive_strength", "KHR_materials_specular", "KHR_materials_clearcoat", "KHR_lights_punctual",
    "KHR_materials_unlit",   /* (load_unlit) */
    "KHR_materials_anisotropy",   /* (load_anisotropy) */
    "KHR_materials_sheen",        /* (load_sheen) */
    "KHR_materials_pbrSpecularGlossiness",   /* (load_spec_gloss) */
    "DR_environment", "DR_units", "KHR_texture_transform", "KHR_draco_mesh_compression",
    /* KTX2 images: read when they hold 8-bit texels (core/ktx2.h); the others are refused, or skipped
     * under --ignore-unsupported (check_ktx2): handled, not ignored */
    "KHR_texture_basisu",
    /* WebP images (read by OpenImageIO), and integer vertex attributes (AccessorView::get reads them) */
    "EXT_texture_webp", "KHR_mesh_quantization",
    /* meshoptimizer-compressed buffer views (meshopt_decode.h); instanced nodes (add_instances) */
    "EXT_meshopt_compression", "EXT_mesh_gpu_instancing",
    /* participating media (load_material_medium) */
    "KHR_materials_volume", "KHR_materials_transmission", "KHR_materials_ior", "KHR_materials_volume_scatter",
    "DR_medium"};

/* A texture's image named by an extension (load_textures). */
const char *const kTextureSourceExtensions[] = {"KHR_texture_basisu", "EXT_texture_webp"};

bool is_supported_extension(const std::string &name)
{
    for (const char *s : kSupportedExtensions)
        if (name == s) return true;
    return false;
}

/* An image as the file holds it, kept by image_cb for the decode. */
struct EncodedImage {
    int index;
    std::string hint;                   /* name for the format and messages */
    std::vector<unsigned char> bytes;
};

class Loader {
public:
    Loader(const char *path, const dr_load_opts &opts, dr_scene *scene, bool defer)
        : path_(path), opts_(opts), scene_(scene), defer_(defer) {}
    ~Loader();
    void run();

    /* tinygltf callbacks (user data = this) */
    static bool fs_exists(const std::string &path, void *user);
    static std::string fs_expand(const std::string &path, void *user);
    static bool fs_read(std::vector<unsigned char> *out, std::string *err, const std::string &path,
                        void *user);
    static bool fs_write(std::string *err, const std::string &path,
                         const std::vector<unsigned char> &data, void *user);
    static bool image_cb(tinygltf::Image *image, const int image_idx, std::string *err,
                         std::string *warn, int req_w, int req_h, const unsigned char *bytes,
                         int size, void *user);

private:
    [[noreturn]] DR_PRINTF(3, 4) void fail(int code, const char *fmt, ...);
    DR_PRINTF(3, 4) void warn_once(const std::string &key, const char *fmt, ...);

    void load_model();
    bool parse_file(tinygltf::TinyGLTF &gltf, bool binary, std::string *err, std::string *warn);
    void check_features();
    void take_images();
    void load_textures();
    void load_materials();
    void load_surface(const tinygltf::Material &g, const std::string &mp, dr_material &m);
    void add_tangents(const tinygltf::Primitive &p, const std::string &pp, size_t nv, const Mat4 &world,
                      bool mirrored, int32_t material);
    dr_texref texref(const tinygltf::TextureInfo &ti, const std::string &path);
    tinygltf::TextureInfo texture_info(const tinygltf::Value &v, const std::string &path);
    void texture_transform(const tinygltf::Value &v, const std::string &ep, dr_texref &r);
    void check_ktx2();
    void traverse_scene();
    void visit_node(int idx, const Mat4 &parent, const std::string &ref, std::vector<char> &on_path);
    Mat4 local_matrix(int idx);
    void add_instances(int idx, const tinygltf::Value &ext, const Mat4 &world);
    void add_primitive(int mesh_idx, int prim_idx, const Mat4 &world, const NormalXform &nx);
    struct VertexAttrs {
        const AccessorView &pos, &nor, &uv, &uv1, &col;
        bool has_nor, has_col;
    };
    void append_vertices(const VertexAttrs &va, size_t base, const Mat4 &world, const NormalXform &nx);
    std::vector<uint32_t> primitive_sequence(const tinygltf::Primitive &p, const std::string &pp, size_t nv,
                                             const dr_draco_mesh *draco);
    void decode_images();
    void start_decode();
    bool reads_spec_gloss() const;
    bool decode_draco(const tinygltf::Primitive &p, const std::string &pp, dr_draco_mesh &out,
                      std::map<std::string, int> &ids);
    AccessorView attribute_view(const tinygltf::Primitive &p, const std::string &pp, const char *name, int want_type,
                                const dr_draco_mesh *draco, const std::map<std::string, int> &draco_ids);
    void add_camera(int cam_idx, int node_idx, const Mat4 &world);
    void add_light(int light_idx, int node_idx, const Mat4 &world);
    void load_environment();
    void load_light_units();
    void finish();
    /* participating media (the "media" section at the end of this file) */
    void load_material_medium(const tinygltf::Material &g, const std::string &mp, size_t index, dr_material &m);
    void load_thin_glass(const tinygltf::Material &g, const std::string &mp, dr_material &m);
    void load_clearcoat(const tinygltf::Material &g, const std::string &mp, dr_material &m);
    void load_sheen(const tinygltf::Material &g, const std::string &mp, dr_material &m);
    void load_spec_gloss(const tinygltf::Material &g, const std::string &mp, dr_material &m);
    dr_texref roughness_from_gloss(const dr_texref &gloss, double glossiness);
    void load_anisotropy(const tinygltf::Material &g, const std::string &mp, dr_material &m);
    bool load_unlit(const tinygltf::Material &g, const std::string &mp, dr_material &m);
    double material_ior(const tinygltf::Material &g, const std::string &mp, const char *what);
    void read_medium_ext(const tinygltf::Value &v, const std::string &ep, dr_medium &med);
    void read_medium_grid(const tinygltf::Value &v, const std::string &ep, dr_medium &med);
    double boundary_ior(const tinygltf::Material &g, const std::string &mp, bool has_dr);
    void load_global_medium();
    void finish_media();

    AccessorView view_accessor(int idx, const std::string &ref, int want_type, const char *what);
    AccessorView dense_view(int idx, const tinygltf::Accessor &a, size_t elem);
    void apply_sparse(int idx, const tinygltf::Accessor &a, size_t elem, AccessorView &v);
    const unsigned char *view_bytes(int bv, int offset, size_t need, const std::string &where);
    double ext_number(const tinygltf::Value &obj, const char *key, double def, const std::string &path);
    dr_vec3 ext_vec3(const tinygltf::Value &obj, const char *key, dr_vec3 def, const std::string &path);
    dr_vec3 color3(const std::vector<double> &v, dr_vec3 def, const std::string &path);

    const char *path_;
    dr_load_opts opts_;
    dr_scene *scene_;
    tinygltf::Model model_;

    /* the first file tinygltf could not open since the last successful read */
    std::string fs_fail_path_;
    int fs_fail_errno_ = 0;
    /* error set by the image callback (tinygltf only sees "false") */
    int image_error_ = 0;
    std::string image_message_;

    std::vector<dr_image> images_;          /* decoded by decode_images, by glTF image index */
    std::map<std::pair<int, double>, int> gloss_textures_;   /* (texture, glossiness) -> the derived
                                                                 roughness texture (roughness_from_gloss) */
    std::vector<EncodedImage> encoded_images_;
    /* the decode running in the background (load_model, defer_), handed to
     * the scene at the end of run(); by image index: decoding there */
    std::unique_ptr<dr_pending_images> pending_;
    std::vector<char> pending_index_;
    bool defer_ = false;
    std::vector<std::string> ktx2_images_;  /* by image index: why a KTX2 image is left undecoded ("": it is
                                               not one, or drender decodes it) */
    std::vector<int> texture_ktx2_;         /* by texture: its KTX2 image, -1 */
    std::vector<char> linear_images_;       /* used as colour: needs sRGB decode */
    std::vector<char> data_images_;         /* used as data (metallic-roughness, normals): keeps its values */
    std::vector<dr_material> materials_;
    bool default_material_used_ = false;
    std::vector<dr_camera> cameras_;
    std::vector<dr_punctual> lights_;
    std::vector<dr_medium> media_;          /* owned here until finish_media() */
    std::vector<int> material_medium_;      /* per file material: index into media_, -1 */

    std::vector<float> positions_, normals_, uvs_;
    /* only when the scene calls for them (empty otherwise): */
    bool want_uv1_ = false;                 /* some texref reads TEXCOORD_1 */
    std::vector<float> uvs1_, colors_;
    bool have_colors_ = false;              /* some primitive so far had COLOR_0 */
    std::set<int> placed_cameras_;          /* indices into the file's "cameras" that a node places */
    std::vector<float> tangents_;           /* 4 per vertex once a primitive has a normal map */
    std::vector<uint32_t> indices_;
    std::vector<int32_t> tri_material_;
    std::vector<uint8_t> tri_flags_;
    dr_vec3 bbox_min_ = dr_v3s(HUGE_VAL), bbox_max_ = dr_v3s(-HUGE_VAL);

    std::set<std::string> warned_;
    std::vector<std::string> warnings_;     /* emitted only when the load succeeds */
};

void Loader::fail(int code, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    std::string msg = vstrf(fmt, ap);
    va_end(ap);
    dr_set_error("%s: %s", path_, msg.c_str());
    throw Failure{code};
}

void Loader::warn_once(const std::string &key, const char *fmt, ...)
{
    if (!warned_.insert(key).second) return;
    va_list ap;
    va_start(ap, fmt);
    warnings_.push_back(std::string(path_) + ": " + vstrf(fmt, ap));
    va_end(ap);
}

/* ---- file system: our own callbacks so a missing buffer file can be reported
 * with its errno instead of tinygltf's free-form text ---- */

bool Loader::fs_exists(const std::string &path, void *user)
{
    FILE *f = fopen(path.c_str(), "rb");
    if (f) {
        fclose(f);
        return true;
    }
    Loader *L = static_cast<Loader *>(user);
    if (L->fs_fail_path_.empty()) {
        L->fs_fail_path_ = path;
        L->fs_fail_errno_ = errno;
    }
    return false;
}

std::string Loader::fs_expand(const std::string &path, void *) { return path; }

bool Loader::fs_read(std::vector<unsigned char> *out, std::string *err, const std::string &path,
                     void *user)
{
    Loader *L = static_cast<Loader *>(user);
    FILE *f = fopen(path.c_str(), "rb");
    if (f) {
        out->clear();
        unsigned char buf[65536];
        size_t n;
        while ((n = fread(buf, 1, sizeof buf, f)) > 0) out->insert(out->end(), buf, buf + n);
        bool ok = !ferror(f);
        int e = errno;
        fclose(f);
        if (ok) {
            L->fs_fail_path_.clear();  /* an earlier probe of another directory does not count */
            return true;
        }
        errno = e;
    }
    if (L->fs_fail_path_.empty()) {
        L->fs_fail_path_ = path;
        L->fs_fail_errno_ = errno;
    }
    if (err) *err = strerror(errno);
    return false;
}

bool Loader::fs_write(std::string *err, const std::string &, const std::vector<unsigned char> &, void *)
{
    if (err) *err = "the loader does not write files";
    return false;
}

/* ---- images: decoded by OpenImageIO (image_io.cpp), never by stb ---- */

/* fn(i) for every i in [0, n), one item per CPU at a time: the renderer's
 * dr_parallel_for (the caller's thread among the workers; fewer helpers if
 * threads cannot be made). fn must not throw. */
template <class Fn> void parallel_each(size_t n, Fn fn)
{
    if (n == 0) return;
    const int threads = int(std::min(n, size_t(dr_default_threads())));
    dr_range_fn range = [](void *ctx, int, int64_t begin, int64_t end) {
        for (int64_t i = begin; i < end; i++) (*static_cast<Fn *>(ctx))(size_t(i));
    };
    if (dr_parallel_for(int64_t(n), 1, threads, range, &fn) != 0) throw std::bad_alloc();
}

/* Error messages of work done on other threads (dr_last_error is per thread). */
struct ThreadMessages {
    explicit ThreadMessages(size_t n) : text(n * kSize, '\0') {}
    void keep(size_t i) { snprintf(&text[i * kSize], kSize, "%s", dr_last_error()); }
    const char *at(size_t i) const { return &text[i * kSize]; }
    static constexpr size_t kSize = 1024;
    std::vector<char> text;
};

std::string image_name_hint(const tinygltf::Image &image, int idx, const unsigned char *b, int size)
{
    if (!image.uri.empty()) return image.uri;
    /* OpenImageIO picks the reader by extension, so give the hint one. */
    const char *ext = "";
    if (image.mimeType == "image/png") ext = ".png";
    else if (image.mimeType == "image/jpeg") ext = ".jpg";
    else if (size >= 4 && b[0] == 0x89 && b[1] == 'P' && b[2] == 'N' && b[3] == 'G') ext = ".png";
    else if (size >= 3 && b[0] == 0xff && b[1] == 0xd8 && b[2] == 0xff) ext = ".jpg";
    else if (size >= 4 && b[0] == 0x76 && b[1] == 0x2f && b[2] == 0x31 && b[3] == 0x01) ext = ".exr";
    else if (size >= 2 && b[0] == '#' && b[1] == '?') ext = ".hdr";
    return strf("image%d%s", idx, ext);
}

bool has_suffix(const char *s, const char *suffix);

/* KTX2 container (KHR_texture_basisu's images): by MIME type, file name or
 * the 12-byte identifier. */
bool is_ktx2(const tinygltf::Image &image, const unsigned char *b, int size)
{
    static const unsigned char magic[12] = {0xAB, 'K', 'T', 'X', ' ', '2', '0', 0xBB, '\r', '\n', 0x1A, '\n'};
    return image.mimeType == "image/ktx2" || (!image.uri.empty() && has_suffix(image.uri.c_str(), ".ktx2")) ||
           (size >= 12 && memcmp(b, magic, 12) == 0);
}

bool Loader::image_cb(tinygltf::Image *image, const int image_idx, std::string *err, std::string *,
                      int, int, const unsigned char *bytes, int size, void *user)
{
    Loader *L = static_cast<Loader *>(user);
    try {
        if (image->bufferView >= 0) {
            /* tinygltf hands us &buffer[byteOffset] with byteLength unchecked. */
            const tinygltf::BufferView &bv = L->model_.bufferViews[size_t(image->bufferView)];
            size_t blen = L->model_.buffers[size_t(bv.buffer)].data.size();
            if (bv.byteOffset > blen || bv.byteLength > blen - bv.byteOffset) {
                L->image_error_ = DR_ERR_FORMAT;
                L->image_message_ = strf("%s: /bufferViews/%d: byte range %zu..%zu exceeds buffer %d (length %zu)",
                                         L->path_, image->bufferView, bv.byteOffset,
                                         bv.byteOffset + bv.byteLength, bv.buffer, blen);
                if (err) *err += L->image_message_;
                return false;
            }
        }
        char why[320];
        if (is_ktx2(*image, bytes, size) && dr_ktx2_probe(bytes, size_t(size), why, sizeof why) != 0) {
            /* a KTX2 drender cannot decode (Basis Universal, block formats;
             * core/ktx2.h): kept undecoded, with the reason; check_ktx2
             * decides whether the scene can do without it */
            if (L->ktx2_images_.size() <= size_t(image_idx)) L->ktx2_images_.resize(size_t(image_idx) + 1);
            L->ktx2_images_[size_t(image_idx)] = why;
            image->image.clear();
            return true;
        }
        /* decoded after the parse, all images at once (decode_images);
         * tinygltf only needs to believe the image is loaded */
        L->encoded_images_.push_back(
            EncodedImage{image_idx, image_name_hint(*image, image_idx, bytes, size),
                         std::vector<unsigned char>(bytes, bytes + size)});
        image->image.clear();
        return true;
    } catch (...) {
        L->image_error_ = DR_ERR_NOMEM;
        L->image_message_ = strf("%s: /images/%d: out of memory", L->path_, image_idx);
        return false;
    }
}

/* The images image_cb kept, decoded all at once, one per CPU at a time (a
 * scene's 2k textures were decoded one after the other), into out; rc and
 * why by position. Images from 8-bit files come in eight-bit storage
 * (image.h: the same values in a quarter of the memory; NormalTangentTest's
 * three 2k textures took 151 MB as floats), decoded straight to bytes. */
void decode_encoded(const std::vector<EncodedImage> &enc, std::vector<dr_image> &out, std::vector<int> &rc,
                    ThreadMessages &why)
{
    parallel_each(enc.size(), [&](size_t k) {
        const EncodedImage &e = enc[k];
        /* KTX2 (plain 8-bit texels) is drender's own reader: no image library */
        if (dr_ktx2_is(e.bytes.data(), e.bytes.size()))
            rc[k] = dr_ktx2_read8(e.bytes.data(), e.bytes.size(), e.hint.c_str(), &out[k]);
        else
            rc[k] = dr_image_read_memory8(e.bytes.data(), e.bytes.size(), e.hint.c_str(), &out[k]);
        if (rc[k] != 0)
            why.keep(k);
    });
}

/* The first failure in file order (the image index), or rc.size(). */
size_t first_failure(const std::vector<EncodedImage> &enc, const std::vector<int> &rc)
{
    size_t failed = rc.size();
    for (size_t k = 0; k < rc.size(); k++)
        if (rc[k] != 0 && (failed == rc.size() || enc[k].index < enc[failed].index)) failed = k;
    return failed;
}

/* The colour textures' sRGB decode, also one image per CPU; in place where
 * nothing reads the encoded values (an image only used as colour). 0, or
 * the first failure's code with its message set, naming path. */
int linearize_images(const char *path, dr_image *images, const std::vector<char> &linear, const std::vector<char> &data)
{
    const size_t n = linear.size();
    std::vector<int> rc(n, 0);
    ThreadMessages why(n);
    parallel_each(n, [&](size_t i) {
        if (!linear[i]) return;
        rc[i] = data[i] ? dr_image_make_linear(&images[i]) : dr_image_make_linear_in_place(&images[i]);
        if (rc[i] != 0) why.keep(i);
    });
    for (size_t i = 0; i < n; i++)
        if (rc[i] != 0) {
            dr_set_error("%s: /images/%zu: %s", path, i, why.at(i));
            return rc[i];
        }
    return 0;
}

}  // namespace

/* The decode of a scene's images running on a thread of its own while the
 * loader and dr_scene_prepare do what needs no pixels (scene.h): the image
 * library's load (0.1-0.3 s, one CPU, core/image_plugin.h) and the decodes
 * then overlap the geometry, the ray structure and the rest. Joined and
 * handed to the scene by dr_pending_images_finish; deleting it joins the
 * thread and releases what it decoded. */
struct dr_pending_images {
    std::string path;                   /* the scene file, for messages */
    std::vector<EncodedImage> encoded;
    std::vector<dr_image> out;          /* by position in encoded */
    std::vector<int> rc;
    ThreadMessages why{0};
    int job_rc = 0;                     /* the job's own failure (no threads, no memory) */
    std::vector<char> linear, data;     /* the loader's linear_images_, data_images_ */
    std::thread thread;
    ~dr_pending_images()
    {
        if (thread.joinable()) thread.join();
        for (dr_image &im : out) dr_image_release(&im);
    }
};

namespace {

Loader::~Loader()
{
    for (dr_image &img : images_) dr_image_release(&img);  /* those not handed over */
    for (dr_medium &m : media_) dr_grid_release(&m.grid);
}

/* The images image_cb kept, decoded now (decode_encoded) and handed to
 * images_. A failure is reported for the first failing image in file
 * order. */
void Loader::decode_images()
{
    const size_t n = encoded_images_.size();
    std::vector<dr_image> out(n, dr_image{});
    /* the decoded images not yet handed to images_, released if an
     * allocation below throws (each is zeroed once handed on) */
    struct Pending {
        std::vector<dr_image> &images;
        ~Pending()
        {
            for (dr_image &im : images) dr_image_release(&im);
        }
    } pending{out};
    std::vector<int> rc(n, 0);
    ThreadMessages why(n);
    decode_encoded(encoded_images_, out, rc, why);
    const size_t failed = first_failure(encoded_images_, rc);
    for (size_t k = 0; k < n; k++) {
        const int idx = encoded_images_[k].index;
        if (rc[k] != 0) continue;
        if (images_.size() <= size_t(idx)) images_.resize(size_t(idx) + 1, dr_image{});
        dr_image_release(&images_[size_t(idx)]);
        images_[size_t(idx)] = out[k];   /* ours now: released by the destructor if loading fails */
        out[k] = dr_image{};
        tinygltf::Image &im = model_.images[size_t(idx)];
        im.width = images_[size_t(idx)].width;
        im.height = images_[size_t(idx)].height;
        im.component = images_[size_t(idx)].channels;
        im.bits = 32;
        im.pixel_type = TINYGLTF_COMPONENT_TYPE_FLOAT;
    }
    if (failed < n) {
        dr_set_error("%s: /images/%d: %s", path_, encoded_images_[failed].index, why.at(failed));
        throw Failure{rc[failed]};
    }
    encoded_images_.clear();
}

/* A specular-glossiness material derives its roughness texture from its
 * image's pixels while the materials load (roughness_from_gloss): such a
 * file's images are decoded before. */
bool Loader::reads_spec_gloss() const
{
    for (const tinygltf::Material &m : model_.materials)
        if (m.extensions.count("KHR_materials_pbrSpecularGlossiness")) return true;
    return false;
}

/* The decode, started on a thread of its own (dr_pending_images); decoded
 * here and now if that thread cannot be made. */
void Loader::start_decode()
{
    auto p = std::make_unique<dr_pending_images>();
    const size_t n = encoded_images_.size();
    p->path = path_;
    p->out.assign(n, dr_image{});
    p->rc.assign(n, 0);
    p->why = ThreadMessages(n);
    pending_index_.assign(model_.images.size(), 0);
    for (const EncodedImage &e : encoded_images_) pending_index_[size_t(e.index)] = 1;
    p->encoded.swap(encoded_images_);
    dr_pending_images *job = p.get();
    try {
        p->thread = std::thread([job] {
            try {
                decode_encoded(job->encoded, job->out, job->rc, job->why);
            } catch (...) {
                job->job_rc = DR_ERR_NOMEM;
            }
        });
    } catch (const std::system_error &) {
        p->encoded.swap(encoded_images_);
        pending_index_.clear();
        decode_images();
        return;
    }
    pending_ = std::move(p);
}

/* ---- parsing ---- */

std::string trim_message(std::string s)
{
    while (!s.empty() && (s.back() == '\n' || s.back() == ' ')) s.pop_back();
    for (char &c : s)
        if (c == '\n') c = ';';
    return s;
}

std::string directory_of(const char *path)
{
    const char *slash = strrchr(path, '/');
    return slash ? std::string(path, size_t(slash - path + 1)) : std::string();
}

bool has_suffix(const char *s, const char *suffix)
{
    size_t n = strlen(s), m = strlen(suffix);
    return n >= m && strcasecmp(s + n - m, suffix) == 0;
}

/* Parses the file with tinygltf, through dr_draco_strip_indices when it has
 * Draco primitives and dr_meshopt_mark_fallbacks when it has meshopt-compressed
 * buffer views (whose bytes load_model then decodes). */
bool Loader::parse_file(tinygltf::TinyGLTF &gltf, bool binary, std::string *err, std::string *warn)
{
    std::vector<unsigned char> bytes;
    std::string ignored;
    if (!fs_read(&bytes, &ignored, path_, this)) return false;
    if (binary) {
        std::vector<unsigned char> use = bytes, glb = dr_glb_strip_draco_indices(use);
        if (!glb.empty()) use.swap(glb);
        glb = dr_glb_meshopt_mark_fallbacks(use);
        if (!glb.empty()) use.swap(glb);
        if (use.size() > UINT32_MAX) fail(DR_ERR_FORMAT, "the file is larger than 4 GiB");
        return gltf.LoadBinaryFromMemory(&model_, err, warn, use.data(), unsigned(use.size()), directory_of(path_));
    }
    std::string text(bytes.begin(), bytes.end());
    const bool draco = dr_draco_strip_indices(text), meshopt = dr_meshopt_mark_fallbacks(text);
    if (!draco && !meshopt)
        return gltf.LoadASCIIFromFile(&model_, err, warn, path_);
    if (text.size() > UINT32_MAX) fail(DR_ERR_FORMAT, "the file is larger than 4 GiB");
    return gltf.LoadASCIIFromString(&model_, err, warn, text.data(), unsigned(text.size()), directory_of(path_));
}

void Loader::load_model()
{
    /* Open it ourselves first: a clean "cannot open" message, and the magic. */
    FILE *f = fopen(path_, "rb");
    if (!f) fail(DR_ERR_IO, "cannot open: %s", strerror(errno));
    unsigned char magic[4] = {0, 0, 0, 0};
    size_t got = fread(magic, 1, 4, f);
    bool read_error = ferror(f);
    int e = errno;
    fclose(f);
    if (read_error) fail(DR_ERR_IO, "cannot read: %s", strerror(e));
    bool binary = (got == 4 && memcmp(magic, "glTF", 4) == 0) || has_suffix(path_, ".glb");

    tinygltf::TinyGLTF gltf;
    tinygltf::FsCallbacks fs = {fs_exists, fs_expand, fs_read, fs_write, this};
    gltf.SetFsCallbacks(fs);
    gltf.SetImageLoader(image_cb, this);

    std::string err, warn;
    bool ok = parse_file(gltf, binary, &err, &warn);
    if (!ok) {
        if (image_error_) {
            dr_set_error("%s", image_message_.c_str());
            throw Failure{image_error_};
        }
        if (!fs_fail_path_.empty()) {
            if (fs_fail_path_ == path_)
                fail(DR_ERR_IO, "cannot read: %s", strerror(fs_fail_errno_));
            /* Buffers are the only external files whose absence is fatal to
             * tinygltf, and it stops at the first: the one being parsed is the
             * next index. */
            size_t b = model_.buffers.size();
            std::string dir = directory_of(path_), file = fs_fail_path_;
            if (!dir.empty() && file.compare(0, dir.size(), dir) == 0) file.erase(0, dir.size());
            fail(DR_ERR_IO, "/buffers/%zu/uri: cannot read '%s': %s", b, file.c_str(),
                 strerror(fs_fail_errno_));
        }
        /* (tinygltf catches what its JSON parser throws and hands on its
         * what(): "std::bad_alloc" is an allocation that failed, not a
         * malformed file) */
        if (err.find("std::bad_alloc") != std::string::npos) throw std::bad_alloc();
        fail(DR_ERR_FORMAT, "%s", trim_message(err.empty() ? "tinygltf failed to load the file" : err).c_str());
    }
    size_t start = 0;
    while (start < warn.size()) {
        size_t end = warn.find('\n', start);
        if (end == std::string::npos) end = warn.size();
        if (end > start) warnings_.push_back(std::string(path_) + ": " + warn.substr(start, end - start));
        start = end + 1;
    }
    const std::string meshopt = dr_meshopt_decode(model_);   /* (the accessors then read plain bytes) */
    if (!meshopt.empty()) fail(DR_ERR_FORMAT, "%s", meshopt.c_str());
    if (defer_ && !encoded_images_.empty() && !reads_spec_gloss())
        start_decode();
    else
        decode_images();
}

void Loader::check_features()
{
    const auto &req = model_.extensionsRequired;
    std::vector<std::string> names = model_.extensionsUsed;
    names.insert(names.end(), req.begin(), req.end());
    for (const std::string &name : names) {
        if (is_supported_extension(name)) continue;
        bool required = std::find(req.begin(), req.end(), name) != req.end();
        if (required)
            warn_once("ext:" + name,
                      "extension %s is required by this file but drender does not support it; "
                      "rendering without it", name.c_str());
        else
            warn_once("ext:" + name, "extension %s is not supported; ignored", name.c_str());
    }
    if (!model_.animations.empty())
        warn_once("animations", "/animations: animations are ignored (the scene is rendered at rest)");
    if (!model_.skins.empty())
        warn_once("skins", "/skins: skins are ignored (meshes are rendered in their bind pose)");
}

void Loader::take_images()
{
    size_t n = model_.images.size();
    images_.resize(std::max(images_.size(), n), dr_image{});
    ktx2_images_.resize(n);
    for (size_t i = 0; i < n; i++)
        if (!dr_image_has_pixels(&images_[i]) && ktx2_images_[i].empty() &&
            !(i < pending_index_.size() && pending_index_[i])) {
            const tinygltf::Image &im = model_.images[i];
            if (!im.uri.empty())
                fail(DR_ERR_IO, "/images/%zu/uri: cannot read '%s'", i, im.uri.c_str());
            fail(DR_ERR_FORMAT, "/images/%zu: image data could not be loaded", i);
        }
    linear_images_.assign(n, 0);
    data_images_.assign(n, 0);
    scene_->images = static_cast<dr_image *>(calloc(n ? n : 1, sizeof(dr_image)));
    if (!scene_->images) throw std::bad_alloc();
    for (size_t i = 0; i < n; i++) {
        scene_->images[i] = images_[i];
        images_[i] = dr_image{};  /* the scene owns it now */
    }
    scene_->n_images = int(n);
}

enum dr_wrap wrap_mode(int gl) { return gl == 33071 ? DR_WRAP_CLAMP : gl == 33648 ? DR_WRAP_MIRROR : DR_WRAP_REPEAT; }

void Loader::load_textures()
{
    std::vector<dr_texture> textures;
    for (size_t i = 0; i < model_.textures.size(); i++) {
        const tinygltf::Texture &t = model_.textures[i];
        dr_texture tex = {};
        int source = t.source;
        std::string sp = strf("/textures/%zu/source", i);
        /* Images in a format core glTF does not name: KTX2 and WebP. A
         * "source" beside the extension is the fallback for viewers that
         * cannot decode it: used when present (drender decodes the WebP too,
         * and either gives the texture). */
        for (const char *name : kTextureSourceExtensions) {
            auto ex = t.extensions.find(name);
            if (ex == t.extensions.end()) continue;
            std::string ep = strf("/textures/%zu/extensions/%s/source", i, name);
            if (!ex->second.IsObject() || !ex->second.Get("source").IsInt())
                fail(DR_ERR_FORMAT, "%s: expected an image index", ep.c_str());
            if (source < 0) {
                source = ex->second.Get("source").GetNumberAsInt();
                sp = ep;
            }
        }
        if (source < 0)
            fail(DR_ERR_FORMAT, "/textures/%zu: texture has no source image", i);
        if (size_t(source) >= model_.images.size())
            fail(DR_ERR_FORMAT, "%s: image %d does not exist", sp.c_str(), source);
        texture_ktx2_.push_back(!ktx2_images_[size_t(source)].empty() ? source : -1);
        tex.image = source;
        tex.wrap_s = tex.wrap_t = DR_WRAP_REPEAT;
        if (t.sampler >= 0) {
            if (size_t(t.sampler) >= model_.samplers.size())
                fail(DR_ERR_FORMAT, "/textures/%zu/sampler: sampler %d does not exist", i, t.sampler);
            const tinygltf::Sampler &s = model_.samplers[size_t(t.sampler)];
            for (int w : {s.wrapS, s.wrapT})
                if (w != 10497 && w != 33071 && w != 33648)
                    fail(DR_ERR_FORMAT, "/samplers/%d: invalid wrap mode %d", t.sampler, w);
            tex.wrap_s = wrap_mode(s.wrapS);
            tex.wrap_t = wrap_mode(s.wrapT);
        }
        textures.push_back(tex);
    }
    scene_->textures = copy_out(textures);
    scene_->n_textures = int(textures.size());
}

double Loader::ext_number(const tinygltf::Value &obj, const char *key, double def, const std::string &path)
{
    if (!obj.Has(key)) return def;
    const tinygltf::Value &v = obj.Get(key);
    if (!v.IsNumber()) fail(DR_ERR_FORMAT, "%s/%s: expected a number", path.c_str(), key);
    return v.GetNumberAsDouble();
}

dr_vec3 Loader::ext_vec3(const tinygltf::Value &obj, const char *key, dr_vec3 def, const std::string &path)
{
    if (!obj.Has(key)) return def;
    const tinygltf::Value &v = obj.Get(key);
    if (!v.IsArray() || v.ArrayLen() != 3 || !v.Get(0).IsNumber() || !v.Get(1).IsNumber() ||
        !v.Get(2).IsNumber())
        fail(DR_ERR_FORMAT, "%s/%s: expected an array of 3 numbers", path.c_str(), key);
    return dr_v3(v.Get(0).GetNumberAsDouble(), v.Get(1).GetNumberAsDouble(), v.Get(2).GetNumberAsDouble());
}

dr_vec3 Loader::color3(const std::vector<double> &v, dr_vec3 def, const std::string &path)
{
    if (v.empty()) return def;
    if (v.size() < 3) fail(DR_ERR_FORMAT, "%s: expected at least 3 numbers", path.c_str());
    return dr_v3(v[0], v[1], v[2]);
}

/* KHR_texture_transform on a textureInfo: uv' = T(offset) R(rotation) S(scale) uv,
 * with the spec's rotation [cos sin; -sin cos]; texCoord overrides the set. */
void Loader::texture_transform(const tinygltf::Value &v, const std::string &ep, dr_texref &r)
{
    if (!v.IsObject()) fail(DR_ERR_FORMAT, "%s: expected an object", ep.c_str());
    double off[2] = {0.0, 0.0}, sc[2] = {1.0, 1.0};
    double rot = ext_number(v, "rotation", 0.0, ep);
    for (auto kv : {std::make_pair("offset", off), std::make_pair("scale", sc)}) {
        if (!v.Has(kv.first)) continue;
        const tinygltf::Value &a = v.Get(kv.first);
        if (!a.IsArray() || a.ArrayLen() != 2 || !a.Get(0).IsNumber() || !a.Get(1).IsNumber())
            fail(DR_ERR_FORMAT, "%s/%s: expected an array of 2 numbers", ep.c_str(), kv.first);
        kv.second[0] = a.Get(0).GetNumberAsDouble();
        kv.second[1] = a.Get(1).GetNumberAsDouble();
    }
    if (!std::isfinite(rot) || !std::isfinite(off[0]) || !std::isfinite(off[1]) || !std::isfinite(sc[0]) ||
        !std::isfinite(sc[1]))
        fail(DR_ERR_FORMAT, "%s: offset, rotation and scale must be finite", ep.c_str());
    if (v.Has("texCoord")) {
        const tinygltf::Value &t = v.Get("texCoord");
        if (!t.IsInt() || t.GetNumberAsInt() < 0)
            fail(DR_ERR_FORMAT, "%s/texCoord: expected a non-negative integer", ep.c_str());
        r.texcoord = t.GetNumberAsInt();
    }
    double c = cos(rot), s = sin(rot);
    double xf[6] = {c * sc[0], s * sc[1], off[0], -s * sc[0], c * sc[1], off[1]};
    memcpy(r.xf, xf, sizeof xf);
    r.transformed = true;
}

/* A textureInfo object inside an extension (tinygltf parses those of core
 * glTF only): its index, texCoord and extensions (KHR_texture_transform). */
tinygltf::TextureInfo Loader::texture_info(const tinygltf::Value &v, const std::string &path)
{
    tinygltf::TextureInfo ti;
    if (!v.IsObject() || !v.Has("index") || !v.Get("index").IsInt())
        fail(DR_ERR_FORMAT, "%s/index: expected a texture index", path.c_str());
    ti.index = v.Get("index").GetNumberAsInt();
    if (v.Has("texCoord")) {
        if (!v.Get("texCoord").IsInt()) fail(DR_ERR_FORMAT, "%s/texCoord: expected an integer", path.c_str());
        ti.texCoord = v.Get("texCoord").GetNumberAsInt();
    }
    if (v.Has("extensions") && v.Get("extensions").IsObject())
        for (const auto &kv : v.Get("extensions").Get<tinygltf::Value::Object>()) ti.extensions[kv.first] = kv.second;
    return ti;
}

dr_texref Loader::texref(const tinygltf::TextureInfo &ti, const std::string &path)
{
    dr_texref r = {-1, ti.texCoord, false, {1.0, 0.0, 0.0, 0.0, 1.0, 0.0}};
    if (ti.index < 0) return r;
    if (size_t(ti.index) >= model_.textures.size())
        fail(DR_ERR_FORMAT, "%s/index: texture %d does not exist", path.c_str(), ti.index);
    if (ti.texCoord < 0) fail(DR_ERR_FORMAT, "%s/texCoord: must be >= 0", path.c_str());
    auto tt = ti.extensions.find("KHR_texture_transform");
    if (tt != ti.extensions.end()) texture_transform(tt->second, path + "/extensions/KHR_texture_transform", r);
    if (r.texcoord > 1) {
        warn_once("texcoord", "%s/texCoord: TEXCOORD_%d is not supported (sets 0 and 1 are); texture ignored",
                  path.c_str(), r.texcoord);
        return r;
    }
    int k = texture_ktx2_[size_t(ti.index)];
    if (k >= 0)
        fail(DR_ERR_FORMAT, "%s/index: texture %d uses the KTX2 image /images/%d ('%s'), which drender cannot "
             "decode: %s. It changes the rendered image, so --ignore-unsupported does not skip it (convert it to "
             "PNG or JPEG, or to KTX2 with uncompressed 8-bit texels)", path.c_str(),
             ti.index, k, model_.images[size_t(k)].uri.c_str(), ktx2_images_[size_t(k)].c_str());
    want_uv1_ |= r.texcoord == 1;
    r.texture = ti.index;
    return r;
}

/* KTX2 images that no texture drender renders with reads (texref refused
 * those): normal and occlusion maps, or unused. Refused unless
 * --ignore-unsupported, then skipped with one warning. */
void Loader::check_ktx2()
{
    std::string list, first_why;
    for (size_t i = 0; i < ktx2_images_.size(); i++)
        if (!ktx2_images_[i].empty()) {
            list += (list.empty() ? "" : ", ") + strf("/images/%zu", i);
            if (first_why.empty()) first_why = ktx2_images_[i];
        }
    if (list.empty()) return;
    if (!opts_.ignore_unsupported)
        fail(DR_ERR_FORMAT, "%s: KTX2 images drender cannot decode (the first: %s); they are used only as normal or "
             "occlusion maps (or not at all): --ignore-unsupported skips them (a normal map is then left out: the "
             "interpolated normals shade)", list.c_str(), first_why.c_str());
    warn_once("ktx2", "%s: KTX2 images drender cannot decode skipped (--ignore-unsupported): used only as normal "
              "or occlusion maps (or not at all); their materials shade without the normal map", list.c_str());
}

dr_material default_material(const char *name)
{
    dr_material m = {};
    copy_name(m.name, name);
    m.base_color = dr_v3s(1.0);
    m.metallic = m.roughness = 1.0;
    m.emissive_factor = dr_v3s(0.0);
    m.emissive_strength = 1.0;
    m.specular = 1.0;
    m.specular_color = dr_v3s(1.0);
    m.double_sided = false;
    m.base_color_tex = m.metallic_roughness_tex = m.emissive_tex = dr_texref{-1, 0, false, {1, 0, 0, 0, 1, 0}};
    m.normal_tex = m.coat_tex = m.coat_roughness_tex = dr_texref{-1, 0, false, {1, 0, 0, 0, 1, 0}};
    m.anisotropy_tex = m.specular_tex = m.specular_color_tex = dr_texref{-1, 0, false, {1, 0, 0, 0, 1, 0}};
    m.sheen_color_tex = m.sheen_roughness_tex = dr_texref{-1, 0, false, {1, 0, 0, 0, 1, 0}};
    m.normal_scale = 1.0;
    m.alpha_mode = DR_ALPHA_OPAQUE;
    m.alpha = 1.0;
    m.alpha_cutoff = 0.5;
    return m;
}

/* normalTexture (+ scale), alphaMode, alphaCutoff and baseColorFactor's alpha. */
void Loader::load_surface(const tinygltf::Material &g, const std::string &mp, dr_material &m)
{
    const tinygltf::NormalTextureInfo &nt = g.normalTexture;
    /* a KTX2 normal map cannot be decoded: left out here, so that check_ktx2
     * refuses it, or skips it (flat shading normals) under --ignore-unsupported */
    bool ktx2 = nt.index >= 0 && size_t(nt.index) < texture_ktx2_.size() && texture_ktx2_[size_t(nt.index)] >= 0;
    if (nt.index >= 0 && !ktx2) {
        tinygltf::TextureInfo ti;
        ti.index = nt.index;
        ti.texCoord = nt.texCoord;
        ti.extensions = nt.extensions;
        m.normal_tex = texref(ti, mp + "/normalTexture");   /* linear data: never sRGB-decoded */
        m.normal_scale = nt.scale;
        if (!std::isfinite(m.normal_scale))
            fail(DR_ERR_FORMAT, "%s/normalTexture/scale: must be finite", mp.c_str());
    }
    const std::vector<double> &bc = g.pbrMetallicRoughness.baseColorFactor;
    if (bc.size() >= 4) m.alpha = bc[3];
    if (!(m.alpha >= 0.0 && m.alpha <= 1.0))
        fail(DR_ERR_FORMAT, "%s/pbrMetallicRoughness/baseColorFactor/3: alpha must be in [0, 1] (got %g)",
             mp.c_str(), m.alpha);
    m.alpha_cutoff = g.alphaCutoff;
    if (!std::isfinite(m.alpha_cutoff))
        fail(DR_ERR_FORMAT, "%s/alphaCutoff: must be finite", mp.c_str());
    if (g.alphaMode == "MASK") m.alpha_mode = DR_ALPHA_MASK;
    else if (g.alphaMode == "BLEND") m.alpha_mode = DR_ALPHA_BLEND;
    else if (g.alphaMode != "OPAQUE" && !g.alphaMode.empty())
        warn_once("alpha", "%s/alphaMode: unknown mode '%s'; rendered as OPAQUE", mp.c_str(), g.alphaMode.c_str());
}

void Loader::load_materials()
{
    for (size_t i = 0; i < model_.materials.size(); i++) {
        const tinygltf::Material &g = model_.materials[i];
        const tinygltf::PbrMetallicRoughness &pbr = g.pbrMetallicRoughness;
        std::string mp = strf("/materials/%zu", i);
        std::string pp = mp + "/pbrMetallicRoughness";
        dr_material m = default_material(g.name.empty() ? strf("material_%zu", i).c_str() : g.name.c_str());
        m.base_color = color3(pbr.baseColorFactor, dr_v3s(1.0), pp + "/baseColorFactor");
        m.metallic = pbr.metallicFactor;
        m.roughness = pbr.roughnessFactor;
        m.emissive_factor = color3(g.emissiveFactor, dr_v3s(0.0), mp + "/emissiveFactor");
        m.double_sided = g.doubleSided;
        m.base_color_tex = texref(pbr.baseColorTexture, pp + "/baseColorTexture");
        m.metallic_roughness_tex = texref(pbr.metallicRoughnessTexture, pp + "/metallicRoughnessTexture");
        m.emissive_tex = texref(g.emissiveTexture, mp + "/emissiveTexture");
        /* colour textures are sRGB-encoded; metallicRoughness is linear data */
        for (const dr_texref *t : {&m.base_color_tex, &m.emissive_tex})
            if (t->texture >= 0) linear_images_[size_t(scene_->textures[t->texture].image)] = 1;

        load_surface(g, mp, m);
        for (const dr_texref *t : {&m.metallic_roughness_tex, &m.normal_tex})
            if (t->texture >= 0) data_images_[size_t(scene_->textures[t->texture].image)] = 1;
        if (g.occlusionTexture.index >= 0)
            warn_once("occlusionTexture", "%s/occlusionTexture: occlusion maps are ignored (the path "
                      "tracer computes occlusion)", mp.c_str());

        auto it = g.extensions.find("KHR_materials_emissive_strength");
        if (it != g.extensions.end()) {
            std::string ep = mp + "/extensions/KHR_materials_emissive_strength";
            if (!it->second.IsObject()) fail(DR_ERR_FORMAT, "%s: expected an object", ep.c_str());
            m.emissive_strength = ext_number(it->second, "emissiveStrength", 1.0, ep);
        }
        it = g.extensions.find("KHR_materials_specular");
        if (it != g.extensions.end()) {
            std::string ep = mp + "/extensions/KHR_materials_specular";
            if (!it->second.IsObject()) fail(DR_ERR_FORMAT, "%s: expected an object", ep.c_str());
            m.specular = ext_number(it->second, "specularFactor", 1.0, ep);
            m.specular_color = ext_vec3(it->second, "specularColorFactor", dr_v3s(1.0), ep);
            /* specularTexture's A (linear data), specularColorTexture's RGB (sRGB) */
            const std::pair<const char *, dr_texref *> textures[] = {{"specularTexture", &m.specular_tex},
                                                                     {"specularColorTexture", &m.specular_color_tex}};
            for (const auto &t : textures) {
                if (!it->second.Has(t.first)) continue;
                *t.second = texref(texture_info(it->second.Get(t.first), ep + "/" + t.first), ep + "/" + t.first);
                if (t.second->texture < 0) continue;
                auto &kind = t.second == &m.specular_tex ? data_images_ : linear_images_;
                kind[size_t(scene_->textures[t.second->texture].image)] = 1;
            }
        }
        load_spec_gloss(g, mp, m);   /* (in place of pbrMetallicRoughness and KHR_materials_specular) */
        if (!load_unlit(g, mp, m)) {
            load_clearcoat(g, mp, m);        /* (before load_material_medium: thin glass drops the coat */
            load_sheen(g, mp, m);            /*  and the sheen) */
            load_material_medium(g, mp, i, m);
            load_anisotropy(g, mp, m);
        }
        for (const auto &kv : g.extensions)
            if (!is_supported_extension(kv.first))
                warn_once("ext:" + kv.first, "%s/extensions/%s: extension is not supported; ignored",
                          mp.c_str(), kv.first.c_str());
        materials_.push_back(m);
    }
}

/* ---- accessors ---- */

AccessorView Loader::view_accessor(int idx, const std::string &ref, int want_type, const char *what)
{
    if (idx < 0 || size_t(idx) >= model_.accessors.size())
        fail(DR_ERR_FORMAT, "%s: accessor %d does not exist", ref.c_str(), idx);
    const tinygltf::Accessor &a = model_.accessors[size_t(idx)];
    if (a.type != want_type)
        fail(DR_ERR_FORMAT, "/accessors/%d: %s must be %s, not %s", idx, what, type_name(want_type),
             type_name(a.type));
    size_t csize = component_size(a.componentType);
    if (csize == 0)
        fail(DR_ERR_FORMAT, "/accessors/%d/componentType: invalid component type %d", idx, a.componentType);
    size_t elem = csize * size_t(tinygltf::GetNumComponentsInType(uint32_t(a.type)));
    AccessorView v = dense_view(idx, a, elem);
    if (a.sparse.isSparse) apply_sparse(idx, a, elem, v);
    return v;
}

/* The accessor's bufferView part (all zeros without one), range-checked. */
AccessorView Loader::dense_view(int idx, const tinygltf::Accessor &a, size_t elem)
{
    AccessorView v;
    v.count = a.count;
    v.comp_type = a.componentType;
    v.normalized = a.normalized;
    v.stride = elem;
    if (a.bufferView < 0) return v;  /* all zeros */

    if (size_t(a.bufferView) >= model_.bufferViews.size())
        fail(DR_ERR_FORMAT, "/accessors/%d/bufferView: bufferView %d does not exist", idx, a.bufferView);
    const tinygltf::BufferView &bv = model_.bufferViews[size_t(a.bufferView)];
    if (bv.buffer < 0 || size_t(bv.buffer) >= model_.buffers.size())
        fail(DR_ERR_FORMAT, "/bufferViews/%d/buffer: buffer %d does not exist", a.bufferView, bv.buffer);
    const std::vector<unsigned char> &data = model_.buffers[size_t(bv.buffer)].data;
    if (bv.byteOffset > data.size() || bv.byteLength > data.size() - bv.byteOffset)
        fail(DR_ERR_FORMAT, "/bufferViews/%d: byte range %zu..%zu exceeds buffer %d (length %zu)",
             a.bufferView, bv.byteOffset, bv.byteOffset + bv.byteLength, bv.buffer, data.size());
    if (bv.byteStride != 0) {
        if (bv.byteStride < elem)
            fail(DR_ERR_FORMAT, "/bufferViews/%d/byteStride: %zu is less than the %zu-byte elements of "
                 "accessor %d", a.bufferView, bv.byteStride, elem, idx);
        v.stride = bv.byteStride;
    }
    /* bytes the accessor touches (the last element needs only elem bytes),
     * checked without overflowing size_t */
    size_t len = bv.byteLength;
    bool fits = a.byteOffset <= len &&
                (a.count == 0 || (elem <= len - a.byteOffset &&
                                  (a.count - 1) <= (len - a.byteOffset - elem) / v.stride));
    if (!fits) {
        double end = double(a.byteOffset) + (a.count ? double(a.count - 1) * double(v.stride) + double(elem) : 0.0);
        fail(DR_ERR_FORMAT, "/accessors/%d: byte range %zu..%.0f exceeds bufferView %d (length %zu)", idx,
             a.byteOffset, end, a.bufferView, len);
    }
    v.base = data.data() + bv.byteOffset + a.byteOffset;
    return v;
}

/* need bytes at offset into bufferView bv (tightly packed, as the sparse
 * indices and values are), range-checked; `where` is the JSON path that names bv. */
const unsigned char *Loader::view_bytes(int bv, int offset, size_t need, const std::string &where)
{
    if (bv < 0 || size_t(bv) >= model_.bufferViews.size())
        fail(DR_ERR_FORMAT, "%s/bufferView: bufferView %d does not exist", where.c_str(), bv);
    if (offset < 0) fail(DR_ERR_FORMAT, "%s/byteOffset: %d is negative", where.c_str(), offset);
    const tinygltf::BufferView &v = model_.bufferViews[size_t(bv)];
    if (v.buffer < 0 || size_t(v.buffer) >= model_.buffers.size())
        fail(DR_ERR_FORMAT, "/bufferViews/%d/buffer: buffer %d does not exist", bv, v.buffer);
    const std::vector<unsigned char> &data = model_.buffers[size_t(v.buffer)].data;
    if (v.byteOffset > data.size() || v.byteLength > data.size() - v.byteOffset)
        fail(DR_ERR_FORMAT, "/bufferViews/%d: byte range %zu..%zu exceeds buffer %d (length %zu)", bv,
             v.byteOffset, v.byteOffset + v.byteLength, v.buffer, data.size());
    size_t off = size_t(offset);
    if (off > v.byteLength || need > v.byteLength - off)
        fail(DR_ERR_FORMAT, "%s: byte range %zu..%.0f exceeds bufferView %d (length %zu)", where.c_str(), off,
             double(off) + double(need), bv, v.byteLength);
    return data.data() + v.byteOffset + off;
}

/* glTF sparse accessors: the base (bufferView or zeros) copied into a dense
 * array, then sparse.count elements replaced at sparse.indices (strictly
 * increasing, each below the accessor's count) by sparse.values. */
void Loader::apply_sparse(int idx, const tinygltf::Accessor &a, size_t elem, AccessorView &v)
{
    const std::string sp = strf("/accessors/%d/sparse", idx);
    const int ict = a.sparse.indices.componentType;
    if (ict != TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE && ict != TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT &&
        ict != TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT)
        fail(DR_ERR_FORMAT, "%s/indices/componentType: must be unsigned byte, short or int (got %d)", sp.c_str(),
             ict);
    if (a.sparse.count < 1 || size_t(a.sparse.count) > a.count)
        fail(DR_ERR_FORMAT, "%s/count: %d is not in 1..%zu (the accessor's count)", sp.c_str(), a.sparse.count,
             a.count);
    /* without a bufferView nothing bounds count by the file's size */
    const size_t max_bytes = size_t(1) << 30;
    if (a.count > max_bytes / elem)
        fail(DR_ERR_FORMAT, "/accessors/%d/count: %zu elements of a sparse accessor is more than drender "
             "accepts (%zu bytes)", idx, a.count, max_bytes);
    const size_t n = size_t(a.sparse.count), isize = component_size(ict);
    const unsigned char *ib = view_bytes(a.sparse.indices.bufferView, a.sparse.indices.byteOffset, n * isize,
                                         sp + "/indices");
    const unsigned char *vb = view_bytes(a.sparse.values.bufferView, a.sparse.values.byteOffset, n * elem,
                                         sp + "/values");
    auto dense = std::make_shared<std::vector<unsigned char>>(a.count * elem, 0);
    if (v.base)
        for (size_t i = 0; i < a.count; i++) memcpy(dense->data() + i * elem, v.base + i * v.stride, elem);
    AccessorView ix;
    ix.base = ib;
    ix.stride = isize;
    ix.count = n;
    ix.comp_type = ict;
    for (size_t j = 0; j < n; j++) {
        uint32_t i = ix.index(j);
        if (i >= a.count)
            fail(DR_ERR_FORMAT, "%s/indices: index %u (element %zu) is out of range: the accessor has %zu "
                 "elements", sp.c_str(), i, j, a.count);
        if (j > 0 && i <= ix.index(j - 1))
            fail(DR_ERR_FORMAT, "%s/indices: index %u (element %zu) does not increase strictly", sp.c_str(), i, j);
        memcpy(dense->data() + size_t(i) * elem, vb + j * elem, elem);
    }
    v.owned = dense;
    v.base = dense->data();
    v.stride = elem;
}

/* ---- geometry ---- */

/* KHR_draco_mesh_compression: decodes the primitive's compressed bufferView;
 * ids maps glTF attribute names to the decoded attributes' unique ids. */
bool Loader::decode_draco(const tinygltf::Primitive &p, const std::string &pp, dr_draco_mesh &out,
                          std::map<std::string, int> &ids)
{
    auto it = p.extensions.find("KHR_draco_mesh_compression");
    if (it == p.extensions.end()) return false;
    const std::string ep = pp + "/extensions/KHR_draco_mesh_compression";
    const tinygltf::Value &v = it->second;
    if (!v.IsObject() || !v.Get("bufferView").IsInt())
        fail(DR_ERR_FORMAT, "%s/bufferView: expected a bufferView index", ep.c_str());
    const tinygltf::Value &attrs = v.Get("attributes");
    if (!attrs.IsObject()) fail(DR_ERR_FORMAT, "%s/attributes: expected an object", ep.c_str());
    for (const std::string &key : attrs.Keys()) {
        const tinygltf::Value &id = attrs.Get(key);
        if (!id.IsInt() || id.GetNumberAsInt() < 0)
            fail(DR_ERR_FORMAT, "%s/attributes/%s: expected a non-negative attribute id", ep.c_str(), key.c_str());
        ids[key] = id.GetNumberAsInt();
    }
    int bv = v.Get("bufferView").GetNumberAsInt();
    if (bv < 0 || size_t(bv) >= model_.bufferViews.size())
        fail(DR_ERR_FORMAT, "%s/bufferView: bufferView %d does not exist", ep.c_str(), bv);
    size_t len = model_.bufferViews[size_t(bv)].byteLength;
    const unsigned char *bytes = view_bytes(bv, 0, len, ep);
    std::string err;
    if (!dr_draco_decode(bytes, len, &out, &err))
        fail(DR_ERR_FORMAT, "%s: cannot decode the Draco mesh: %s", ep.c_str(), err.c_str());
    if (out.n_points > UINT32_MAX) fail(DR_ERR_FORMAT, "%s: too many points", ep.c_str());
    return true;
}

/* Attribute `name` of the primitive: from the Draco mesh when it compressed
 * it, else its accessor. base == NULL and count 0 when the primitive has none. */
AccessorView Loader::attribute_view(const tinygltf::Primitive &p, const std::string &pp, const char *name,
                                    int want_type, const dr_draco_mesh *draco,
                                    const std::map<std::string, int> &draco_ids)
{
    auto it = p.attributes.find(name);
    auto di = draco_ids.find(name);
    if (draco && di != draco_ids.end()) {
        const std::string ep = pp + "/extensions/KHR_draco_mesh_compression/attributes/" + name;
        const int ncomp = tinygltf::GetNumComponentsInType(uint32_t(want_type));
        const bool colour = name == std::string("COLOR_0");   /* rgb or rgba: rgb is read from either */
        for (const dr_draco_attribute &a : draco->attributes) {
            if (a.unique_id != di->second) continue;
            if (a.components != ncomp && !(colour && a.components == 4))
                fail(DR_ERR_FORMAT, "%s: the decoded attribute has %d components, %s needs %d", ep.c_str(),
                     a.components, name, ncomp);
            AccessorView v;
            v.owned = std::make_shared<std::vector<unsigned char>>(a.values.size() * sizeof(float));
            if (!a.values.empty()) memcpy(v.owned->data(), a.values.data(), v.owned->size());
            v.base = v.owned->data();
            v.stride = size_t(a.components) * sizeof(float);
            v.count = draco->n_points;
            v.comp_type = TINYGLTF_COMPONENT_TYPE_FLOAT;
            return v;
        }
        fail(DR_ERR_FORMAT, "%s: the Draco mesh has no attribute %d", ep.c_str(), di->second);
    }
    if (it == p.attributes.end()) return AccessorView{};
    const std::string ap = pp + "/attributes/" + name;
    if (name == std::string("COLOR_0")) {   /* vec3 or vec4 */
        int t = it->second >= 0 && size_t(it->second) < model_.accessors.size()
                    ? model_.accessors[size_t(it->second)].type : TINYGLTF_TYPE_VEC3;
        want_type = t == TINYGLTF_TYPE_VEC4 ? TINYGLTF_TYPE_VEC4 : TINYGLTF_TYPE_VEC3;
    }
    AccessorView v = view_accessor(it->second, ap, want_type, name);
    if (name == std::string("COLOR_0") && v.comp_type != TINYGLTF_COMPONENT_TYPE_FLOAT &&
        !((v.comp_type == TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE || v.comp_type == TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT) &&
          v.normalized))
        fail(DR_ERR_FORMAT, "/accessors/%d: COLOR_0 must be float or normalized unsigned byte or short", it->second);
    return v;
}

/* The primitive's vertex sequence, as listed (indices, or the Draco faces) or implicit. */
std::vector<uint32_t> Loader::primitive_sequence(const tinygltf::Primitive &p, const std::string &pp, size_t nv,
                                                 const dr_draco_mesh *draco)
{
    std::vector<uint32_t> seq;
    if (draco) return draco->indices;   /* each checked < n_points by the shim */
    if (p.indices >= 0) {
        AccessorView ix = view_accessor(p.indices, pp + "/indices", TINYGLTF_TYPE_SCALAR, "indices");
        if (ix.comp_type != TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE &&
            ix.comp_type != TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT &&
            ix.comp_type != TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT)
            fail(DR_ERR_FORMAT, "/accessors/%d/componentType: indices must be unsigned byte, short or int",
                 p.indices);
        seq.resize(ix.count);
        for (size_t i = 0; i < ix.count; i++) {
            seq[i] = ix.index(i);
            if (seq[i] >= nv)
                fail(DR_ERR_FORMAT, "/accessors/%d: index %u (element %zu) is out of range: the "
                     "primitive has %zu vertices", p.indices, seq[i], i, nv);
        }
    } else {
        if (nv > UINT32_MAX) fail(DR_ERR_FORMAT, "%s: too many vertices", pp.c_str());
        seq.resize(nv);
        for (size_t i = 0; i < nv; i++) seq[i] = uint32_t(i);
    }
    return seq;
}

/* Strips and fans become lists; an incomplete last triangle is dropped. */
std::vector<uint32_t> triangle_list(int mode, const std::vector<uint32_t> &seq)
{
    std::vector<uint32_t> tri;
    if (mode == TINYGLTF_MODE_TRIANGLES) {
        tri.assign(seq.begin(), seq.begin() + ptrdiff_t(seq.size() / 3 * 3));
        return tri;
    }
    for (size_t i = 0; i + 2 < seq.size(); i++) {
        if (mode == TINYGLTF_MODE_TRIANGLE_FAN)
            tri.insert(tri.end(), {seq[0], seq[i + 1], seq[i + 2]});
        else if (i % 2 == 0)
            tri.insert(tri.end(), {seq[i], seq[i + 1], seq[i + 2]});
        else  /* odd strip triangles swap to keep the winding */
            tri.insert(tri.end(), {seq[i + 1], seq[i], seq[i + 2]});
    }
    return tri;
}

/* Appends a primitive's vertices in world space; colours and the second uv
 * set only when the scene has them. */
void Loader::append_vertices(const VertexAttrs &va, size_t base, const Mat4 &world, const NormalXform &nx)
{
    /* vertex colours and the second uv set exist only once some primitive
     * needs them; earlier vertices then get the neutral value */
    if (va.has_col && !have_colors_) colors_.assign(base * 3, 1.0f);
    have_colors_ |= va.has_col;
    if (want_uv1_ && uvs1_.empty()) uvs1_.assign(base * 2, 0.0f);
    for (size_t i = 0; i < va.pos.count; i++) {
        dr_vec3 w = mat_point(world, va.pos.get(i, 0), va.pos.get(i, 1), va.pos.get(i, 2));
        positions_.insert(positions_.end(), {float(w.x), float(w.y), float(w.z)});
        bbox_min_ = dr_v3(fmin(bbox_min_.x, w.x), fmin(bbox_min_.y, w.y), fmin(bbox_min_.z, w.z));
        bbox_max_ = dr_v3(fmax(bbox_max_.x, w.x), fmax(bbox_max_.y, w.y), fmax(bbox_max_.z, w.z));
        dr_vec3 n = dr_v3s(0.0);
        if (va.has_nor) {
            double a = va.nor.get(i, 0), b = va.nor.get(i, 1), c = va.nor.get(i, 2);
            n = dr_normalize(dr_v3(nx.n[0][0] * a + nx.n[0][1] * b + nx.n[0][2] * c,
                                   nx.n[1][0] * a + nx.n[1][1] * b + nx.n[1][2] * c,
                                   nx.n[2][0] * a + nx.n[2][1] * b + nx.n[2][2] * c));
        }
        normals_.insert(normals_.end(), {float(n.x), float(n.y), float(n.z)});
        uvs_.insert(uvs_.end(), {float(va.uv.get(i, 0)), float(va.uv.get(i, 1))});
        if (want_uv1_) uvs1_.insert(uvs1_.end(), {float(va.uv1.get(i, 0)), float(va.uv1.get(i, 1))});
        if (have_colors_) {
            if (va.has_col)
                colors_.insert(colors_.end(), {float(va.col.get(i, 0)), float(va.col.get(i, 1)), float(va.col.get(i, 2))});
            else
                colors_.insert(colors_.end(), {1.0f, 1.0f, 1.0f});
        }
    }
}

void Loader::add_primitive(int mesh_idx, int prim_idx, const Mat4 &world, const NormalXform &nx)
{
    const tinygltf::Primitive &p = model_.meshes[size_t(mesh_idx)].primitives[size_t(prim_idx)];
    std::string pp = strf("/meshes/%d/primitives/%d", mesh_idx, prim_idx);
    int mode = p.mode < 0 ? TINYGLTF_MODE_TRIANGLES : p.mode;
    if (mode == TINYGLTF_MODE_POINTS)
        fail(DR_ERR_FORMAT, "%s/mode: points are not supported (drender renders triangles)", pp.c_str());
    if (mode == TINYGLTF_MODE_LINE || mode == TINYGLTF_MODE_LINE_LOOP || mode == TINYGLTF_MODE_LINE_STRIP)
        fail(DR_ERR_FORMAT, "%s/mode: lines are not supported (drender renders triangles)", pp.c_str());
    if (mode != TINYGLTF_MODE_TRIANGLES && mode != TINYGLTF_MODE_TRIANGLE_STRIP &&
        mode != TINYGLTF_MODE_TRIANGLE_FAN)
        fail(DR_ERR_FORMAT, "%s/mode: unknown primitive mode %d", pp.c_str(), mode);
    if (!p.targets.empty())
        warn_once("morph", "%s/targets: morph targets are ignored", pp.c_str());
    for (const auto &kv : p.extensions)
        if (!is_supported_extension(kv.first))
            warn_once("ext:" + kv.first, "%s/extensions/%s: extension is not supported; ignored", pp.c_str(),
                      kv.first.c_str());

    dr_draco_mesh draco_mesh;
    std::map<std::string, int> draco_ids;
    const dr_draco_mesh *draco = decode_draco(p, pp, draco_mesh, draco_ids) ? &draco_mesh : nullptr;
    auto present = [&](const char *name) { return p.attributes.count(name) > 0 || draco_ids.count(name) > 0; };
    auto attribute = [&](const char *name, int type) { return attribute_view(p, pp, name, type, draco, draco_ids); };
    if (!present("POSITION")) fail(DR_ERR_FORMAT, "%s/attributes: the primitive has no POSITION", pp.c_str());
    AccessorView pos = attribute("POSITION", TINYGLTF_TYPE_VEC3);
    const size_t nv = pos.count;
    const bool has_nor = present("NORMAL"), has_uv = present("TEXCOORD_0"), has_col = present("COLOR_0");
    const bool has_uv1 = want_uv1_ && present("TEXCOORD_1");   /* read only when a texture uses it */
    AccessorView nor, uv, uv1, col;
    if (has_nor) nor = attribute("NORMAL", TINYGLTF_TYPE_VEC3);
    if (has_uv) uv = attribute("TEXCOORD_0", TINYGLTF_TYPE_VEC2);
    if (has_uv1) uv1 = attribute("TEXCOORD_1", TINYGLTF_TYPE_VEC2);
    if (has_col) col = attribute("COLOR_0", TINYGLTF_TYPE_VEC3);
    auto check_count = [&](const char *name, bool has, const AccessorView &v) {
        if (has && v.count != nv)
            fail(DR_ERR_FORMAT, "%s/attributes/%s: %s has %zu elements but POSITION has %zu", pp.c_str(), name,
                 name, v.count, nv);
    };
    check_count("NORMAL", has_nor, nor);
    check_count("TEXCOORD_0", has_uv, uv);
    check_count("TEXCOORD_1", has_uv1, uv1);
    check_count("COLOR_0", has_col, col);

    std::vector<uint32_t> tri = triangle_list(mode, primitive_sequence(p, pp, nv, draco));

    size_t base = positions_.size() / 3;
    if (base + nv > UINT32_MAX) fail(DR_ERR_FORMAT, "%s: the scene has more than 2^32 vertices", pp.c_str());

    int32_t material;
    if (p.material < 0) {
        default_material_used_ = true;
        material = int32_t(model_.materials.size());
    } else if (size_t(p.material) >= model_.materials.size()) {
        fail(DR_ERR_FORMAT, "%s/material: material %d does not exist", pp.c_str(), p.material);
    } else {
        material = p.material;
    }
    uint8_t flags = uint8_t((has_nor ? DR_TRI_HAS_NORMALS : 0) | (has_uv ? DR_TRI_HAS_UVS : 0));
    if (has_col && size_t(material) < materials_.size() && materials_[size_t(material)].unlit)
        warn_once("unlit:COLOR_0", "%s/attributes/COLOR_0: vertex colours do not tint an unlit material's "
                  "colour (KHR_materials_unlit); ignored there", pp.c_str());

    append_vertices(VertexAttrs{pos, nor, uv, uv1, col, has_nor, has_col}, base, world, nx);
    add_tangents(p, pp, nv, world, nx.mirrored, material);
    for (size_t t = 0; t + 2 < tri.size(); t += 3) {
        uint32_t a = uint32_t(base) + tri[t], b = uint32_t(base) + tri[t + 1], c = uint32_t(base) + tri[t + 2];
        if (nx.mirrored) std::swap(b, c);  /* a mirror turns counter-clockwise into clockwise */
        indices_.insert(indices_.end(), {a, b, c});
        tri_material_.push_back(material);
        tri_flags_.push_back(flags);
    }
}

/* TANGENT (xyz direction, w bitangent sign) of a primitive whose material
 * needs it (a normal map or anisotropy: dr_material_needs_tangents). tangents_ stays empty until the first such primitive and is
 * then kept aligned with positions_; zeros mean "generate"
 * (dr_mesh_prepare_tangents), also for a tangent that is degenerate. */
void Loader::add_tangents(const tinygltf::Primitive &p, const std::string &pp, size_t nv, const Mat4 &world,
                          bool mirrored, int32_t material)
{
    size_t total = positions_.size() / 3;   /* this primitive's vertices included */
    bool mapped = size_t(material) < materials_.size() && dr_material_needs_tangents(&materials_[size_t(material)]);
    if (!mapped && tangents_.empty()) return;
    tangents_.resize(4 * (total - nv), 0.0f);
    auto it = p.attributes.find("TANGENT");
    if (mapped && materials_[size_t(material)].anisotropic && it == p.attributes.end() &&
        !p.attributes.count("TEXCOORD_0"))
        warn_once("anisotropy:frame", "%s: material %d is anisotropic (KHR_materials_anisotropy), but the primitive "
                  "has neither TANGENT nor TEXCOORD_0 to give the direction: rendered isotropic", pp.c_str(),
                  int(material));
    if (!mapped || it == p.attributes.end()) {
        tangents_.resize(4 * total, 0.0f);
        return;
    }
    AccessorView tv = view_accessor(it->second, pp + "/attributes/TANGENT", TINYGLTF_TYPE_VEC4, "TANGENT");
    if (tv.count != nv)
        fail(DR_ERR_FORMAT, "/accessors/%d: TANGENT has %zu elements but POSITION has %zu", it->second, tv.count,
             nv);
    dr_vec3 o = mat_point(world, 0, 0, 0);
    for (size_t i = 0; i < nv; i++) {
        /* a tangent is a direction along the surface: it moves with the linear part of world */
        dr_vec3 t = dr_sub(mat_point(world, tv.get(i, 0), tv.get(i, 1), tv.get(i, 2)), o);
        double len = dr_length(t);
        /* a mirror flips the handedness of the tangent frame */
        double w = (tv.get(i, 3) < 0.0) != mirrored ? -1.0 : 1.0;
        if (!(len > 0.0) || !std::isfinite(len))
            tangents_.insert(tangents_.end(), {0.0f, 0.0f, 0.0f, 0.0f});
        else
            tangents_.insert(tangents_.end(), {float(t.x / len), float(t.y / len), float(t.z / len), float(w)});
    }
}

/* ---- cameras and lights ---- */

void Loader::add_camera(int cam_idx, int node_idx, const Mat4 &world)
{
    const tinygltf::Camera &c = model_.cameras[size_t(cam_idx)];
    if (c.type != "perspective" && c.type != "orthographic")
        fail(DR_ERR_FORMAT, "/cameras/%d/type: unknown camera type '%s'", cam_idx, c.type.c_str());
    dr_camera cam = {};
    cam.gltf_index = cam_idx;
    const std::string &name = !c.name.empty() ? c.name : model_.nodes[size_t(node_idx)].name;
    copy_name(cam.name, name.empty() ? strf("camera_%zu", cameras_.size()) : name);
    cam.origin = mat_column(world, 3);
    cam.right = dr_normalize(mat_column(world, 0));
    cam.up = dr_normalize(mat_column(world, 1));
    cam.forward = dr_normalize(dr_neg(mat_column(world, 2)));
    if (c.type == "orthographic") {
        /* xmag, ymag: half the view's width and height; the image's W/H
         * decides the width as yfov does for perspective, xmag/ymag the default W/H */
        double xmag = fabs(c.orthographic.xmag), ymag = fabs(c.orthographic.ymag);
        if (!(xmag > 0.0 && std::isfinite(xmag)))
            fail(DR_ERR_FORMAT, "/cameras/%d/orthographic/xmag: %g must be finite and non-zero", cam_idx,
                 c.orthographic.xmag);
        if (!(ymag > 0.0 && std::isfinite(ymag)))
            fail(DR_ERR_FORMAT, "/cameras/%d/orthographic/ymag: %g must be finite and non-zero", cam_idx,
                 c.orthographic.ymag);
        cam.orthographic = true;
        cam.ymag = ymag;
        cam.aspect = xmag / ymag;
    } else {
        cam.yfov = c.perspective.yfov;
        cam.aspect = c.perspective.aspectRatio;
        if (!(cam.yfov > 0.0 && cam.yfov < M_PI))
            fail(DR_ERR_FORMAT, "/cameras/%d/perspective/yfov: %g is not in (0, pi)", cam_idx, cam.yfov);
    }
    placed_cameras_.insert(cam_idx);
    cameras_.push_back(cam);
}

void Loader::add_light(int light_idx, int node_idx, const Mat4 &world)
{
    const tinygltf::Light &g = model_.lights[size_t(light_idx)];
    std::string lp = strf("/extensions/KHR_lights_punctual/lights/%d", light_idx);
    dr_punctual l = {};
    const std::string &name = !g.name.empty() ? g.name : model_.nodes[size_t(node_idx)].name;
    copy_name(l.name, name.empty() ? strf("light_%d", light_idx) : name);
    if (g.type == "point") l.type = DR_LIGHT_POINT;
    else if (g.type == "spot") l.type = DR_LIGHT_SPOT;
    else if (g.type == "directional") l.type = DR_LIGHT_DIRECTIONAL;
    else fail(DR_ERR_FORMAT, "%s/type: unknown light type '%s'", lp.c_str(), g.type.c_str());
    l.color = color3(g.color, dr_v3s(1.0), lp + "/color");
    l.intensity = g.intensity;
    l.range = g.range;
    l.position = mat_column(world, 3);
    l.direction = dr_normalize(dr_neg(mat_column(world, 2)));
    l.cos_inner = cos(g.spot.innerConeAngle);
    l.cos_outer = cos(g.spot.outerConeAngle);
    l.gltf_index = light_idx;
    lights_.push_back(l);
}

/* ---- the node graph ---- */

Mat4 Loader::local_matrix(int idx)
{
    const tinygltf::Node &n = model_.nodes[size_t(idx)];
    if (!n.matrix.empty()) {
        if (n.matrix.size() != 16) fail(DR_ERR_FORMAT, "/nodes/%d/matrix: expected 16 numbers", idx);
        Mat4 m;
        for (int i = 0; i < 16; i++) m.m[i] = n.matrix[size_t(i)];
        return m;
    }
    if (!n.translation.empty() && n.translation.size() != 3)
        fail(DR_ERR_FORMAT, "/nodes/%d/translation: expected 3 numbers", idx);
    if (!n.rotation.empty() && n.rotation.size() != 4)
        fail(DR_ERR_FORMAT, "/nodes/%d/rotation: expected 4 numbers", idx);
    if (!n.scale.empty() && n.scale.size() != 3)
        fail(DR_ERR_FORMAT, "/nodes/%d/scale: expected 3 numbers", idx);
    double t[3] = {0, 0, 0}, s[3] = {1, 1, 1}, q[4] = {0, 0, 0, 1};
    for (size_t i = 0; i < n.translation.size(); i++) t[i] = n.translation[i];
    for (size_t i = 0; i < n.scale.size(); i++) s[i] = n.scale[i];
    for (size_t i = 0; i < n.rotation.size(); i++) q[i] = n.rotation[i];
    return trs_matrix(t, q, s);
}

/* T * R * S of a translation, a rotation quaternion (x, y, z, w; normalised
 * here) and a scale: a node's, or an instance's. */
Mat4 trs_matrix(const double t[3], double q[4], const double s[3])
{
    double ql = sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
    if (ql > 0.0)
        for (int c = 0; c < 4; c++) q[c] /= ql;
    double x = q[0], y = q[1], z = q[2], w = q[3];
    double r[3][3] = {{1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)},
                      {2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)},
                      {2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)}};
    Mat4 m = mat_identity();  /* T * R * S */
    for (int row = 0; row < 3; row++) {
        for (int col = 0; col < 3; col++) m.m[col * 4 + row] = r[row][col] * s[col];
        m.m[12 + row] = t[row];
    }
    return m;
}

void Loader::visit_node(int idx, const Mat4 &parent, const std::string &ref, std::vector<char> &on_path)
{
    if (idx < 0 || size_t(idx) >= model_.nodes.size())
        fail(DR_ERR_FORMAT, "%s: node %d does not exist", ref.c_str(), idx);
    if (on_path[size_t(idx)]) fail(DR_ERR_FORMAT, "%s: node %d is its own ancestor", ref.c_str(), idx);
    const tinygltf::Node &n = model_.nodes[size_t(idx)];
    Mat4 world = mat_mul(parent, local_matrix(idx));

    if (n.skin >= 0) warn_once("skins", "/nodes/%d/skin: skins are ignored (meshes are rendered in their "
                               "bind pose)", idx);
    if (n.mesh >= 0) {
        if (size_t(n.mesh) >= model_.meshes.size())
            fail(DR_ERR_FORMAT, "/nodes/%d/mesh: mesh %d does not exist", idx, n.mesh);
        auto inst = n.extensions.find("EXT_mesh_gpu_instancing");
        if (inst != n.extensions.end()) {
            add_instances(idx, inst->second, world);
        } else {
            NormalXform nx = normal_xform(world);
            for (size_t p = 0; p < model_.meshes[size_t(n.mesh)].primitives.size(); p++)
                add_primitive(n.mesh, int(p), world, nx);
        }
    }
    if (n.camera >= 0) {
        if (size_t(n.camera) >= model_.cameras.size())
            fail(DR_ERR_FORMAT, "/nodes/%d/camera: camera %d does not exist", idx, n.camera);
        add_camera(n.camera, idx, world);
    }
    auto ext = n.extensions.find("KHR_lights_punctual");
    if (ext != n.extensions.end()) {
        std::string ep = strf("/nodes/%d/extensions/KHR_lights_punctual", idx);
        if (!ext->second.IsObject() || !ext->second.Get("light").IsInt())
            fail(DR_ERR_FORMAT, "%s/light: expected a light index", ep.c_str());
        int li = ext->second.Get("light").GetNumberAsInt();
        if (li < 0 || size_t(li) >= model_.lights.size())
            fail(DR_ERR_FORMAT, "%s/light: light %d does not exist", ep.c_str(), li);
        add_light(li, idx, world);
    }

    on_path[size_t(idx)] = 1;
    for (size_t c = 0; c < n.children.size(); c++)
        visit_node(n.children[c], world, strf("/nodes/%d/children/%zu", idx, c), on_path);
    on_path[size_t(idx)] = 0;
}

/* EXT_mesh_gpu_instancing: node idx's mesh once per instance, at world x
 * (T R S)_i, from the attributes TRANSLATION (VEC3), ROTATION (VEC4, a
 * quaternion: float or normalized integers) and SCALE (VEC3), accessors of
 * one count; an absent one is the identity. Other attributes (_ID, ...)
 * carry no geometry and are ignored. The mesh is copied per instance (the
 * tracer has no instancing). */
void Loader::add_instances(int idx, const tinygltf::Value &ext, const Mat4 &world)
{
    const std::string ep = strf("/nodes/%d/extensions/EXT_mesh_gpu_instancing", idx);
    if (!ext.IsObject() || !ext.Get("attributes").IsObject())
        fail(DR_ERR_FORMAT, "%s/attributes: expected an object of accessors", ep.c_str());
    const tinygltf::Value &attrs = ext.Get("attributes");
    static const char *const names[3] = {"TRANSLATION", "ROTATION", "SCALE"};
    static const int types[3] = {TINYGLTF_TYPE_VEC3, TINYGLTF_TYPE_VEC4, TINYGLTF_TYPE_VEC3};
    AccessorView v[3];
    bool has[3] = {false, false, false};
    size_t count = 0;
    const char *first = nullptr;
    for (int k = 0; k < 3; k++) {
        if (!attrs.Has(names[k])) continue;
        const std::string ap = ep + "/attributes/" + names[k];
        if (!attrs.Get(names[k]).IsInt()) fail(DR_ERR_FORMAT, "%s: expected an accessor index", ap.c_str());
        const int ai = attrs.Get(names[k]).GetNumberAsInt();
        v[k] = view_accessor(ai, ap, types[k], names[k]);
        if (k == 1 && v[k].comp_type != TINYGLTF_COMPONENT_TYPE_FLOAT && !v[k].normalized)
            fail(DR_ERR_FORMAT, "/accessors/%d: ROTATION must be float or normalized integers", ai);
        if (first && v[k].count != count)
            fail(DR_ERR_FORMAT, "%s: %s has %zu elements but %s has %zu", ap.c_str(), names[k], v[k].count, first,
                 count);
        count = v[k].count, first = first ? first : names[k], has[k] = true;
    }
    if (!first) fail(DR_ERR_FORMAT, "%s/attributes: none of TRANSLATION, ROTATION and SCALE", ep.c_str());
    const int mesh = model_.nodes[size_t(idx)].mesh;
    /* the copies' vertices, before any is made: past 2^32 the scene cannot
     * index them (add_primitive would find it only after gigabytes) */
    uint64_t per_copy = 0;
    for (const tinygltf::Primitive &p : model_.meshes[size_t(mesh)].primitives) {
        auto pos = p.attributes.find("POSITION");
        if (pos != p.attributes.end() && pos->second >= 0 && size_t(pos->second) < model_.accessors.size())
            per_copy += model_.accessors[size_t(pos->second)].count;
    }
    if (per_copy > 0 && (uint64_t)count > (UINT32_MAX - positions_.size() / 3) / per_copy)
        fail(DR_ERR_FORMAT, "%s: %zu instances of mesh %d (%llu vertices each) make more than 2^32 vertices "
             "(drender copies the mesh per instance)", ep.c_str(), count, mesh, (unsigned long long)per_copy);
    for (size_t i = 0; i < count; i++) {
        double t[3] = {0, 0, 0}, q[4] = {0, 0, 0, 1}, sc[3] = {1, 1, 1};
        for (int c = 0; c < 3; c++) {
            if (has[0]) t[c] = v[0].get(i, c);
            if (has[2]) sc[c] = v[2].get(i, c);
        }
        for (int c = 0; has[1] && c < 4; c++) q[c] = v[1].get(i, c);
        const Mat4 m = mat_mul(world, trs_matrix(t, q, sc));
        const NormalXform nx = normal_xform(m);
        for (size_t p = 0; p < model_.meshes[size_t(mesh)].primitives.size(); p++)
            add_primitive(mesh, int(p), m, nx);
    }
}

void Loader::traverse_scene()
{
    std::vector<char> on_path(model_.nodes.size(), 0);
    Mat4 id = mat_identity();
    if (!model_.scenes.empty()) {
        int s = model_.defaultScene < 0 ? 0 : model_.defaultScene;
        if (size_t(s) >= model_.scenes.size()) fail(DR_ERR_FORMAT, "/scene: scene %d does not exist", s);
        const std::vector<int> &roots = model_.scenes[size_t(s)].nodes;
        for (size_t i = 0; i < roots.size(); i++)
            visit_node(roots[i], id, strf("/scenes/%d/nodes/%zu", s, i), on_path);
        return;
    }
    /* no scenes: render every node that is nobody's child */
    std::vector<char> is_child(model_.nodes.size(), 0);
    for (const tinygltf::Node &n : model_.nodes)
        for (int c : n.children)
            if (c >= 0 && size_t(c) < is_child.size()) is_child[size_t(c)] = 1;
    for (size_t i = 0; i < model_.nodes.size(); i++)
        if (!is_child[i]) visit_node(int(i), id, strf("/nodes/%zu", i), on_path);
}

/* ---- DR_environment ---- */

void Loader::load_environment()
{
    auto it = model_.extensions.find("DR_environment");
    if (it == model_.extensions.end()) return;
    const std::string ep = "/extensions/DR_environment";
    const tinygltf::Value &v = it->second;
    if (!v.IsObject()) fail(DR_ERR_FORMAT, "%s: expected an object", ep.c_str());
    dr_environment &env = scene_->env;
    env.present = true;
    env.color = ext_vec3(v, "color", dr_v3s(1.0), ep);
    env.strength = ext_number(v, "strength", 1.0, ep);
    if (!v.Has("uri")) return;
    if (!v.Get("uri").IsString()) fail(DR_ERR_FORMAT, "%s/uri: expected a string", ep.c_str());
    const std::string &uri = v.Get("uri").Get<std::string>();
    if (uri.empty() || uri.size() >= sizeof env.uri)
        fail(DR_ERR_FORMAT, "%s/uri: invalid file name '%s'", ep.c_str(), uri.c_str());
    std::string file = uri[0] == '/' ? uri : directory_of(path_) + uri;
    int rc = dr_image_read(file.c_str(), &env.map);
    if (rc != 0) fail(rc, "%s/uri: %s", ep.c_str(), dr_last_error());
    snprintf(env.uri, sizeof env.uri, "%s", uri.c_str());
    /* an 8-bit sky is sRGB-encoded; give the renderer the decoded copy too */
    if (env.map.file_is_srgb && (rc = dr_image_make_linear(&env.map)) != 0)
        fail(rc, "%s/uri: %s", ep.c_str(), dr_last_error());
}

/* ---- DR_units: how punctual light intensities are read ---- */

void Loader::load_light_units()
{
    scene_->light_units = DR_LIGHT_UNITS_PHOTOMETRIC;   /* glTF's own definition */
    auto it = model_.extensions.find("DR_units");
    if (it == model_.extensions.end()) return;
    const std::string ep = "/extensions/DR_units";
    const tinygltf::Value &v = it->second;
    if (!v.IsObject()) fail(DR_ERR_FORMAT, "%s: expected an object", ep.c_str());
    if (!v.Has("lights")) return;
    const tinygltf::Value &l = v.Get("lights");
    std::string s = l.IsString() ? l.Get<std::string>() : "";
    if (s == "radiometric") scene_->light_units = DR_LIGHT_UNITS_RADIOMETRIC;
    else if (s != "photometric")
        fail(DR_ERR_FORMAT, "%s/lights: expected \"photometric\" or \"radiometric\"", ep.c_str());
}

/* ---- hand-over ---- */

void Loader::finish()
{
    scene_->n_file_materials = int(materials_.size());
    if (default_material_used_) materials_.push_back(default_material("gltf_default"));
    scene_->materials = copy_out(materials_);
    scene_->n_materials = int(materials_.size());
    scene_->cameras = copy_out(cameras_);
    scene_->n_cameras = int(cameras_.size());
    for (dr_punctual &l : lights_)
        l.watts_per_unit = scene_->light_units == DR_LIGHT_UNITS_PHOTOMETRIC ? 1.0 / DR_LUMENS_PER_WATT : 1.0;
    scene_->n_unplaced_cameras = int(model_.cameras.size() - placed_cameras_.size());
    scene_->lights = copy_out(lights_);
    scene_->n_lights = int(lights_.size());

    dr_mesh &mesh = scene_->mesh;
    mesh.n_vertices = uint32_t(positions_.size() / 3);
    mesh.n_triangles = uint32_t(tri_material_.size());
    mesh.positions = copy_out(positions_, 1);  /* Embree reads 16 bytes per vertex */
    mesh.normals = copy_out(normals_, 1);      /* the eight-lane gathers read 16 bytes per vertex */
    mesh.uvs = copy_out(uvs_);
    mesh.uvs1 = copy_out(uvs1_);      /* NULL unless a texture reads TEXCOORD_1 */
    mesh.colors = copy_out(colors_);  /* NULL unless some primitive has COLOR_0 */
    mesh.indices = copy_out(indices_);
    mesh.material = copy_out(tri_material_);
    mesh.flags = copy_out(tri_flags_);
    if (!tangents_.empty()) {
        tangents_.resize(4 * size_t(mesh.n_vertices), 0.0f);
        mesh.tangents = copy_out(tangents_);
    }
    if (mesh.n_vertices == 0) bbox_min_ = bbox_max_ = dr_v3s(0.0);
    scene_->bbox_min = bbox_min_;
    scene_->bbox_max = bbox_max_;

    /* the colour textures' sRGB decode (with the pixels, if they come later:
     * dr_pending_images_finish) */
    if (!pending_) {
        const int rc = linearize_images(path_, scene_->images, linear_images_, data_images_);
        if (rc != 0) throw Failure{rc};
    }
}

void Loader::run()
{
    if (!scene_->path) {
        scene_->path = strdup(path_);
        if (!scene_->path) throw std::bad_alloc();
    }
    load_model();
    check_features();
    take_images();
    load_textures();
    load_materials();
    check_ktx2();
    traverse_scene();
    load_environment();
    load_light_units();
    load_global_medium();
    finish();
    finish_media();
    if (pending_) {   /* the images still decoding: the scene's to finish (dr_scene_prepare) */
        pending_->linear = linear_images_;
        pending_->data = data_images_;
        scene_->pending_images = pending_.release();
    }
    for (const std::string &w : warnings_) dr_warn("%s", w.c_str());
}

/* ---- participating media ----
 * A material with KHR_materials_volume or DR_medium bounds a medium (its mesh
 * must be closed; checked in dr_media_prepare). The boundary is index-matched
 * (ior 1) or a smooth dielectric (ior != 1, KHR_materials_ior, default 1.5
 * with KHR_materials_volume): both need KHR_materials_transmission's
 * transmissionFactor 1 (boundary_ior). DR_medium at the top level is the
 * global medium: the space outside every medium mesh. */

/* density: {uri, resolution} for raw/EXR grids; {uri, grid?, resolution?}
 * for OpenVDB files, whose size comes from the file. */
void Loader::read_medium_grid(const tinygltf::Value &v, const std::string &ep, dr_medium &med)
{
    const std::string gp = ep + "/density";
    if (!v.IsObject()) fail(DR_ERR_FORMAT, "%s: expected an object with uri and resolution", gp.c_str());
    if (!v.Has("uri") || !v.Get("uri").IsString() || v.Get("uri").Get<std::string>().empty())
        fail(DR_ERR_FORMAT, "%s/uri: expected a file name", gp.c_str());
    const std::string &uri = v.Get("uri").Get<std::string>();
    if (uri.size() >= sizeof med.grid_uri) fail(DR_ERR_FORMAT, "%s/uri: file name too long", gp.c_str());
    const bool vdb = dr_grid_file_is_vdb(uri.c_str());
    std::string grid;
    if (v.Has("grid")) {
        if (!vdb) fail(DR_ERR_FORMAT, "%s/grid: only OpenVDB (.vdb) files have named grids", gp.c_str());
        if (!v.Get("grid").IsString() || v.Get("grid").Get<std::string>().empty())
            fail(DR_ERR_FORMAT, "%s/grid: expected the name of a float grid", gp.c_str());
        grid = v.Get("grid").Get<std::string>();
    }
    int n[3] = {0, 0, 0};
    if (v.Has("resolution") || !vdb) {
        const tinygltf::Value &r = v.Get("resolution");
        if (!r.IsArray() || r.ArrayLen() != 3)
            fail(DR_ERR_FORMAT, "%s/resolution: expected [nx, ny, nz]", gp.c_str());
        double voxels = 1.0;
        for (int a = 0; a < 3; a++) {
            double x = r.Get(a).IsNumber() ? r.Get(a).GetNumberAsDouble() : -1.0;
            if (!(x >= 1.0 && x <= 65536.0) || x != double(int(x)))
                fail(DR_ERR_FORMAT, "%s/resolution/%d: expected a positive integer", gp.c_str(), a);
            n[a] = int(x);
            voxels *= x;
        }
        if (voxels > double(DR_VOLUME_MAX_VOXELS))
            fail(DR_ERR_FORMAT, "%s/resolution: %.0f voxels is more than the 2^28 supported", gp.c_str(), voxels);
    }
    std::string file = uri[0] == '/' ? uri : directory_of(path_) + uri;
    int rc = dr_grid_read(file.c_str(), grid.empty() ? nullptr : grid.c_str(), n[0], n[1], n[2], &med.grid);
    if (rc != 0) fail(rc, "%s/uri: %s", gp.c_str(), dr_last_error());
    med.has_grid = true;
    snprintf(med.grid_uri, sizeof med.grid_uri, "%s", uri.c_str());
}

/* The DR_medium fields (material or top level) over what med already holds. */
void Loader::read_medium_ext(const tinygltf::Value &v, const std::string &ep, dr_medium &med)
{
    if (!v.IsObject()) fail(DR_ERR_FORMAT, "%s: expected an object", ep.c_str());
    if (v.Has("extinction") && v.Get("extinction").IsNumber())
        med.extinction = dr_v3s(v.Get("extinction").GetNumberAsDouble());
    else
        med.extinction = ext_vec3(v, "extinction", med.extinction, ep);
    med.albedo = ext_vec3(v, "albedo", med.albedo, ep);
    med.g = ext_number(v, "g", med.g, ep);
    med.density_scale = ext_number(v, "density_scale", 1.0, ep);
    for (int c = 0; c < 3; c++) {
        double e = dr_v3_get(med.extinction, c), a = dr_v3_get(med.albedo, c);
        if (!(e >= 0.0) || !std::isfinite(e))
            fail(DR_ERR_FORMAT, "%s/extinction: must be finite and >= 0 (got %g)", ep.c_str(), e);
        if (!(a >= 0.0 && a <= 1.0)) fail(DR_ERR_FORMAT, "%s/albedo: must be in [0, 1] (got %g)", ep.c_str(), a);
    }
    if (!(med.g > -1.0 && med.g < 1.0)) fail(DR_ERR_FORMAT, "%s/g: must be in (-1, 1) (got %g)", ep.c_str(), med.g);
    if (!(med.density_scale >= 0.0) || !std::isfinite(med.density_scale))
        fail(DR_ERR_FORMAT, "%s/density_scale: must be finite and >= 0", ep.c_str());
    if (v.Has("density")) read_medium_grid(v.Get("density"), ep, med);
    if (v.Has("bounds")) {
        const tinygltf::Value &b = v.Get("bounds");
        if (!b.IsObject()) fail(DR_ERR_FORMAT, "%s/bounds: expected {\"min\": [..], \"max\": [..]}", ep.c_str());
        med.grid.bmin = ext_vec3(b, "min", dr_v3s(0.0), ep + "/bounds");
        med.grid.bmax = ext_vec3(b, "max", dr_v3s(0.0), ep + "/bounds");
        if (!(med.grid.bmin.x < med.grid.bmax.x && med.grid.bmin.y < med.grid.bmax.y &&
              med.grid.bmin.z < med.grid.bmax.z))
            fail(DR_ERR_FORMAT, "%s/bounds: min must be below max on every axis", ep.c_str());
    }
}

static dr_medium empty_medium(const char *name, int material)
{
    dr_medium m = {};
    snprintf(m.name, sizeof m.name, "%s", name);
    m.extinction = dr_v3s(0.0);
    m.albedo = dr_v3s(0.0);
    m.density_scale = 1.0;
    m.material = material;
    return m;
}

/* KHR_materials_volume: attenuation (sigma_t = -ln(colour) / distance);
 * KHR_materials_volume_scatter: albedo and g. */
static void khr_volume(const tinygltf::Material &g, dr_medium &med)
{
    auto vol = g.extensions.find("KHR_materials_volume");
    const tinygltf::Value &v = vol->second;
    double dist = v.Has("attenuationDistance") && v.Get("attenuationDistance").IsNumber()
                      ? v.Get("attenuationDistance").GetNumberAsDouble() : HUGE_VAL;
    dr_vec3 col = dr_v3s(1.0);
    const tinygltf::Value &c = v.Get("attenuationColor");
    if (c.IsArray() && c.ArrayLen() == 3)
        col = dr_v3(c.Get(0).GetNumberAsDouble(), c.Get(1).GetNumberAsDouble(), c.Get(2).GetNumberAsDouble());
    for (int k = 0; k < 3; k++) {
        double a = dr_clamp(dr_v3_get(col, k), 0.0, 1.0);
        dr_v3_set(&med.extinction, k, a >= 1.0 || std::isinf(dist) ? 0.0 : (a <= 0.0 ? 1e4 : -std::log(a) / dist));
    }
    auto sc = g.extensions.find("KHR_materials_volume_scatter");
    if (sc != g.extensions.end()) {
        const tinygltf::Value &ms = sc->second.Get("multiscatterColor");
        if (ms.IsArray() && ms.ArrayLen() == 3)
            for (int k = 0; k < 3; k++)
                dr_v3_set(&med.albedo, k, dr_albedo_from_multiscatter(ms.Get(k).GetNumberAsDouble()));
        const tinygltf::Value &an = sc->second.Get("scatterAnisotropy");
        if (an.IsNumber()) med.g = an.GetNumberAsDouble();
    }
}

/* The boundary's index of refraction, 1: index-matched. KHR_materials_ior
 * (default 1.5 under KHR_materials_volume, as glTF says; DR_medium alone: 1)
 * needs a transmissive boundary (transmissionFactor 1); a DR_medium material
 * whose KHR_materials_volume boundary is not transmissive stays index-matched
 * (DR_medium describes the medium, as before dielectrics existed). */
/* KHR_materials_ior's ior (glTF's default 1.5 without it), checked to lie
 * in [1, 10]; `what` names the surface in the message. */
double Loader::material_ior(const tinygltf::Material &g, const std::string &mp, const char *what)
{
    auto io = g.extensions.find("KHR_materials_ior");
    if (io == g.extensions.end() || !io->second.Has("ior")) return 1.5;
    const tinygltf::Value &x = io->second.Get("ior");
    const double ior = x.IsNumber() ? x.GetNumberAsDouble() : -1.0;
    if (!(ior >= 1.0 && ior <= 10.0))
        fail(DR_ERR_FORMAT, "%s/extensions/KHR_materials_ior/ior: %s index of refraction must be a number in [1, 10] "
             "(got %s)", mp.c_str(), what, x.IsNumber() ? strf("%g", ior).c_str() : "no number");
    return ior;
}

double Loader::boundary_ior(const tinygltf::Material &g, const std::string &mp, bool has_dr)
{
    const bool has_vol = g.extensions.count("KHR_materials_volume") > 0;
    if (!has_vol && !g.extensions.count("KHR_materials_ior")) return 1.0;
    const double ior = material_ior(g, mp, "a medium boundary's");
    double transmission = 0.0;
    auto tr = g.extensions.find("KHR_materials_transmission");
    if (tr != g.extensions.end() && tr->second.Get("transmissionFactor").IsNumber())
        transmission = tr->second.Get("transmissionFactor").GetNumberAsDouble();
    if (transmission == 1.0) return ior;
    if (has_dr) return 1.0;
    fail(DR_ERR_FORMAT, "%s/extensions/KHR_materials_volume: a medium boundary must be transmissive: set "
         "KHR_materials_transmission.transmissionFactor to 1 (with KHR_materials_ior.ior 1 the boundary is "
         "index-matched, otherwise a smooth dielectric), or describe the medium with DR_medium", mp.c_str());
}

/* KHR_materials_transmission without a volume: thin-walled glass
 * (dr_material.thin_ior) where transmissionFactor is 1; a partial one is
 * rendered opaque, as before, with a warning. */
void Loader::load_thin_glass(const tinygltf::Material &g, const std::string &mp, dr_material &m)
{
    auto tr = g.extensions.find("KHR_materials_transmission");
    const std::string ep = mp + "/extensions/KHR_materials_transmission";
    if (!tr->second.IsObject()) fail(DR_ERR_FORMAT, "%s: expected an object", ep.c_str());
    const double factor = ext_number(tr->second, "transmissionFactor", 0.0, ep);
    if (factor != 1.0) {
        if (factor != 0.0)
            warn_once("transmission", "%s/transmissionFactor: partial transmission (%g) is not supported; rendered "
                      "opaque (1 renders thin-walled glass)", ep.c_str(), factor);
        return;
    }
    if (tr->second.Has("transmissionTexture"))
        warn_once("transmissionTexture", "%s/transmissionTexture: not supported; ignored (transmissionFactor 1 "
                  "everywhere)", ep.c_str());
    const unsigned dropped = dr_material_make_thin(&m, material_ior(g, mp, "glass's"));
    if (dropped & 1)
        warn_once("thin:tint", "%s: thin-walled glass is rendered clear: its base colour's tint is ignored",
                  mp.c_str());
    if (dropped & 2)
        warn_once("thin:mr", "%s/pbrMetallicRoughness/metallicRoughnessTexture: ignored on thin-walled glass "
                  "(roughnessFactor alone sets its roughness)", mp.c_str());
    if (dropped & 4)
        warn_once("thin:emission", "%s: thin-walled glass does not emit: its emission is ignored", mp.c_str());
    if (dropped & 8)
        warn_once("thin:coat", "%s/extensions/KHR_materials_clearcoat: ignored on thin-walled glass (its "
                  "reflection is the sheet's own)", mp.c_str());
    if (dropped & 16)
        warn_once("thin:sheen", "%s/extensions/KHR_materials_sheen: ignored on thin-walled glass (its "
                  "reflection is the sheet's own)", mp.c_str());
}

/* KHR_materials_clearcoat (bsdf_coat.c): its two factors, in [0, 1], and
 * their textures (clearcoatTexture's R, clearcoatRoughnessTexture's G). The
 * coat is shaded with the base's normal, normal map included, where glTF
 * gives it the geometric normal unless clearcoatNormalTexture says otherwise
 * (warned where a normal map makes the two differ). */
/* KHR_materials_unlit (scene.h's dr_material.unlit): the base colour
 * becomes the emission, the BSDF black. The extensions that shade or fill
 * the surface (clear coat, specular, transmission, volume) are then
 * ignored, as glTF says, with a warning. False: the material is not unlit. */
bool Loader::load_unlit(const tinygltf::Material &g, const std::string &mp, dr_material &m)
{
    auto it = g.extensions.find("KHR_materials_unlit");
    if (it == g.extensions.end()) return false;
    if (!it->second.IsObject())
        fail(DR_ERR_FORMAT, "%s/extensions/KHR_materials_unlit: expected an object", mp.c_str());
    for (const char *other : {"KHR_materials_clearcoat", "KHR_materials_specular", "KHR_materials_transmission",
                              "KHR_materials_volume", "KHR_materials_emissive_strength", "KHR_materials_anisotropy",
                              "KHR_materials_sheen"})
        if (g.extensions.count(other))
            warn_once(std::string("unlit:") + other, "%s/extensions/%s: ignored on an unlit material "
                      "(KHR_materials_unlit)", mp.c_str(), other);
    m.unlit = true;
    m.emissive_factor = m.base_color;
    m.emissive_strength = 1.0;
    m.emissive_tex = m.base_color_tex;
    m.base_color = dr_v3s(0.0);
    m.metallic = m.specular = 0.0;
    m.specular_tex.texture = m.specular_color_tex.texture = -1;
    m.roughness = 1.0;
    m.metallic_roughness_tex.texture = -1;
    m.normal_tex.texture = -1;
    if (m.alpha_mode == DR_ALPHA_OPAQUE)   /* (kept where its alpha cuts the surface out: coverage.h) */
        m.base_color_tex.texture = -1;
    return true;
}

void Loader::load_clearcoat(const tinygltf::Material &g, const std::string &mp, dr_material &m)
{
    auto it = g.extensions.find("KHR_materials_clearcoat");
    if (it == g.extensions.end()) return;
    const std::string ep = mp + "/extensions/KHR_materials_clearcoat";
    if (!it->second.IsObject()) fail(DR_ERR_FORMAT, "%s: expected an object", ep.c_str());
    const std::pair<const char *, double *> factors[] = {{"clearcoatFactor", &m.coat},
                                                         {"clearcoatRoughnessFactor", &m.coat_roughness}};
    for (const auto &f : factors) {
        *f.second = ext_number(it->second, f.first, 0.0, ep);
        if (!(*f.second >= 0.0 && *f.second <= 1.0))
            fail(DR_ERR_FORMAT, "%s/%s: must be in [0, 1] (got %g)", ep.c_str(), f.first, *f.second);
    }
    m.coated = m.coat > 0.0;
    if (!m.coated) return;
    /* the factor's texture (R) and the roughness's (G): linear data */
    const std::pair<const char *, dr_texref *> textures[] = {{"clearcoatTexture", &m.coat_tex},
                                                             {"clearcoatRoughnessTexture", &m.coat_roughness_tex}};
    for (const auto &t : textures) {
        if (!it->second.Has(t.first)) continue;
        *t.second = texref(texture_info(it->second.Get(t.first), ep + "/" + t.first), ep + "/" + t.first);
        if (t.second->texture >= 0) data_images_[size_t(scene_->textures[t.second->texture].image)] = 1;
    }
    /* The coat's normal is the base's: exact where clearcoatNormalTexture is
     * the normalTexture itself (as Blender writes it) or where neither is given */
    const tinygltf::Value &cn = it->second.Get("clearcoatNormalTexture");
    const tinygltf::NormalTextureInfo &nt = g.normalTexture;
    auto number = [](const tinygltf::Value &o, const char *key, double def) {
        return o.Has(key) && o.Get(key).IsNumber() ? o.Get(key).GetNumberAsDouble() : def;
    };
    const bool same = cn.IsObject() && nt.index >= 0 && number(cn, "index", -1) == nt.index &&
                      number(cn, "texCoord", 0) == nt.texCoord && number(cn, "scale", 1) == nt.scale;
    if (it->second.Has("clearcoatNormalTexture") && !same)
        warn_once("coat:normal", "%s/clearcoatNormalTexture: not supported unless it is the normalTexture; the "
                  "clear coat is shaded with the base's normal", ep.c_str());
    else if (!it->second.Has("clearcoatNormalTexture") && nt.index >= 0)
        warn_once("coat:normal", "%s: the clear coat is shaded with the normal map's normal (glTF gives it the "
                  "geometric normal)", ep.c_str());
}

/* KHR_materials_sheen (scene.h, bsdf_sheen.c): sheenColorFactor (linear RGB)
 * and sheenRoughnessFactor, in [0, 1], and their textures
 * (sheenColorTexture's RGB, sRGB; sheenRoughnessTexture's A, linear data).
 * Sheened only where the colour is not black (glTF's default, [0, 0, 0],
 * is no sheen). */
void Loader::load_sheen(const tinygltf::Material &g, const std::string &mp, dr_material &m)
{
    auto it = g.extensions.find("KHR_materials_sheen");
    if (it == g.extensions.end()) return;
    const std::string ep = mp + "/extensions/KHR_materials_sheen";
    if (!it->second.IsObject()) fail(DR_ERR_FORMAT, "%s: expected an object", ep.c_str());
    m.sheen_color = ext_vec3(it->second, "sheenColorFactor", dr_v3s(0.0), ep);
    const double c[3] = {m.sheen_color.x, m.sheen_color.y, m.sheen_color.z};
    for (int k = 0; k < 3; k++)
        if (!(c[k] >= 0.0 && c[k] <= 1.0))
            fail(DR_ERR_FORMAT, "%s/sheenColorFactor/%d: must be in [0, 1] (got %g)", ep.c_str(), k, c[k]);
    m.sheen_roughness = ext_number(it->second, "sheenRoughnessFactor", 0.0, ep);
    if (!(m.sheen_roughness >= 0.0 && m.sheen_roughness <= 1.0))
        fail(DR_ERR_FORMAT, "%s/sheenRoughnessFactor: must be in [0, 1] (got %g)", ep.c_str(), m.sheen_roughness);
    m.sheened = !dr_is_black(m.sheen_color);
    if (!m.sheened) return;
    const std::pair<const char *, dr_texref *> textures[] = {{"sheenColorTexture", &m.sheen_color_tex},
                                                             {"sheenRoughnessTexture", &m.sheen_roughness_tex}};
    for (const auto &t : textures) {
        if (!it->second.Has(t.first)) continue;
        *t.second = texref(texture_info(it->second.Get(t.first), ep + "/" + t.first), ep + "/" + t.first);
        if (t.second->texture < 0) continue;
        auto &kind = t.second == &m.sheen_roughness_tex ? data_images_ : linear_images_;
        kind[size_t(scene_->textures[t.second->texture].image)] = 1;
    }
}

/* KHR_materials_pbrSpecularGlossiness (archived by Khronos, still in many
 * older assets), loaded onto the model drender renders, as Khronos's own
 * converter (glTF-Transform's metalRough) maps it:
 *   base colour = diffuseFactor x diffuseTexture (sRGB; its alpha the alpha),
 *   metallic 0, roughness = 1 - glossinessFactor x specularGlossinessTexture's A,
 *   KHR_materials_specular with specular 1 and specularColor =
 *   specularFactor x the texture's RGB (sRGB) / 0.04, so that the dielectric
 *   f0 = min(0.04 specularColor, 1) is the file's specular colour F0 and
 *   Schlick's F rises to 1 at grazing angles, as the extension's BRDF does.
 * The diffuse lobe is weighted by (1 - F(wo))(1 - F(wi)) (Material model)
 * rather than the extension's 1 - max(F0): the same deliberate difference as
 * for metal-rough materials. The factors are not parameters (scene.h); the
 * texels of the diffuse texture are, as base-colour texels. The roughness
 * texture is derived (roughness_from_gloss). */
void Loader::load_spec_gloss(const tinygltf::Material &g, const std::string &mp, dr_material &m)
{
    auto it = g.extensions.find("KHR_materials_pbrSpecularGlossiness");
    if (it == g.extensions.end()) return;
    const std::string ep = mp + "/extensions/KHR_materials_pbrSpecularGlossiness";
    const tinygltf::Value &v = it->second;
    if (!v.IsObject()) fail(DR_ERR_FORMAT, "%s: expected an object", ep.c_str());
    double diffuse[4] = {1.0, 1.0, 1.0, 1.0}, spec[3] = {1.0, 1.0, 1.0};
    const std::pair<const char *, double *> arrays[] = {{"diffuseFactor", diffuse}, {"specularFactor", spec}};
    for (const auto &a : arrays) {
        if (!v.Has(a.first)) continue;
        const tinygltf::Value &arr = v.Get(a.first);
        const int n = a.second == diffuse ? 4 : 3;
        if (!arr.IsArray() || int(arr.ArrayLen()) != n)
            fail(DR_ERR_FORMAT, "%s/%s: expected an array of %d numbers", ep.c_str(), a.first, n);
        for (int k = 0; k < n; k++) {
            const tinygltf::Value &x = arr.Get(k);
            a.second[k] = x.IsNumber() ? x.GetNumberAsDouble() : NAN;
            if (!(a.second[k] >= 0.0 && a.second[k] <= 1.0))
                fail(DR_ERR_FORMAT, "%s/%s/%d: must be a number in [0, 1]", ep.c_str(), a.first, k);
        }
    }
    const double gloss = ext_number(v, "glossinessFactor", 1.0, ep);
    if (!(gloss >= 0.0 && gloss <= 1.0))
        fail(DR_ERR_FORMAT, "%s/glossinessFactor: must be in [0, 1] (got %g)", ep.c_str(), gloss);
    dr_texref diffuse_tex = texref(tinygltf::TextureInfo(), ep), gloss_tex = diffuse_tex;
    if (v.Has("diffuseTexture"))
        diffuse_tex = texref(texture_info(v.Get("diffuseTexture"), ep + "/diffuseTexture"), ep + "/diffuseTexture");
    if (v.Has("specularGlossinessTexture"))
        gloss_tex = texref(texture_info(v.Get("specularGlossinessTexture"), ep + "/specularGlossinessTexture"),
                           ep + "/specularGlossinessTexture");
    /* (the material's pbrMetallicRoughness is the fallback the extension
     * asks files to carry for viewers without it: replaced, silently) */
    m.spec_gloss = true;
    m.base_color = dr_v3(diffuse[0], diffuse[1], diffuse[2]);
    m.alpha = diffuse[3];
    m.base_color_tex = diffuse_tex;
    if (diffuse_tex.texture >= 0) linear_images_[size_t(scene_->textures[diffuse_tex.texture].image)] = 1;
    m.metallic = 0.0;
    m.specular = 1.0;
    m.specular_tex = texref(tinygltf::TextureInfo(), ep);
    m.specular_color = dr_v3(spec[0] / 0.04, spec[1] / 0.04, spec[2] / 0.04);
    m.specular_color_tex = gloss_tex;
    m.roughness = 1.0 - gloss;
    m.metallic_roughness_tex = texref(tinygltf::TextureInfo(), ep);
    if (gloss_tex.texture < 0) return;
    linear_images_[size_t(scene_->textures[gloss_tex.texture].image)] = 1;   /* (RGB: sRGB colour) */
    const dr_image &img = scene_->images[scene_->textures[gloss_tex.texture].image];
    if (img.channels == 2 || img.channels >= 4) {   /* (without alpha A reads 1: roughness 1 - gloss) */
        m.roughness = 1.0;
        m.metallic_roughness_tex = roughness_from_gloss(gloss_tex, gloss);
    }
}

/* A texture of the image 1 - glossiness x A of gloss's texture (A as
 * stored: alpha is linear) in every channel: a metallic-roughness texture
 * whose G is the roughness (the metallic factor 0 ignores its B). Bilinear
 * filtering commutes with the map, so its lookups are 1 - glossiness x the
 * filtered A. Eight-bit images stay eight-bit: the same bytes (A's), a
 * table of 1 - glossiness x A's values; float images get floats. Made once
 * per (texture, glossiness); appended to the scene's images and textures
 * past the file's, where no parameter and no writer looks. */
dr_texref Loader::roughness_from_gloss(const dr_texref &gloss, double glossiness)
{
    dr_texref r = gloss;
    auto found = gloss_textures_.find({gloss.texture, glossiness});
    if (found != gloss_textures_.end()) {
        r.texture = found->second;
        return r;
    }
    const dr_texture src_tex = scene_->textures[gloss.texture];
    const dr_image &src = scene_->images[src_tex.image];
    const size_t px = size_t(src.width) * size_t(src.height), c = size_t(src.channels);
    dr_image d = {};
    d.width = src.width, d.height = src.height, d.channels = 3;
    if (src.bytes) {
        d.bytes = static_cast<uint8_t *>(malloc(px * 3));
        d.lut = static_cast<float *>(calloc(512, sizeof(float)));
        if (!d.bytes || !d.lut) {
            free(d.bytes), free(d.lut);
            throw std::bad_alloc();
        }
        for (int i = 0; i < 256; i++) d.lut[i] = float(1.0 - glossiness * double(src.lut[i]));
        for (size_t i = 0; i < px; i++) d.bytes[3 * i] = d.bytes[3 * i + 1] = d.bytes[3 * i + 2] = src.bytes[c * i + c - 1];
    } else {
        d.data = static_cast<float *>(malloc(px * 3 * sizeof(float)));
        if (!d.data) throw std::bad_alloc();
        for (size_t i = 0; i < px; i++)
            d.data[3 * i] = d.data[3 * i + 1] = d.data[3 * i + 2] = float(1.0 - glossiness * double(src.data[c * i + c - 1]));
    }
    dr_image *images = static_cast<dr_image *>(realloc(scene_->images, sizeof(dr_image) * size_t(scene_->n_images + 1)));
    if (!images) {
        dr_image_release(&d);
        throw std::bad_alloc();
    }
    scene_->images = images;
    scene_->images[scene_->n_images] = d;   /* the scene's now */
    dr_texture t = src_tex;
    t.image = scene_->n_images++;
    scene_->n_derived_images++;
    dr_texture *textures = static_cast<dr_texture *>(realloc(scene_->textures, sizeof(dr_texture) * size_t(scene_->n_textures + 1)));
    if (!textures) throw std::bad_alloc();
    scene_->textures = textures;
    scene_->textures[scene_->n_textures] = t;
    texture_ktx2_.push_back(-1);
    r.texture = scene_->n_textures++;
    gloss_textures_[{gloss.texture, glossiness}] = r.texture;
    return r;
}

/* KHR_materials_anisotropy (scene.h, anisotropy.h): anisotropyStrength in
 * [0, 1], anisotropyRotation (radians, finite) and anisotropyTexture (RG
 * the direction, B the strength: linear data). Anisotropic only where the
 * strength is above 0; ignored, with a warning, on thin-walled glass, whose
 * reflection is the sheet's own. */
void Loader::load_anisotropy(const tinygltf::Material &g, const std::string &mp, dr_material &m)
{
    auto it = g.extensions.find("KHR_materials_anisotropy");
    if (it == g.extensions.end()) return;
    const std::string ep = mp + "/extensions/KHR_materials_anisotropy";
    if (!it->second.IsObject()) fail(DR_ERR_FORMAT, "%s: expected an object", ep.c_str());
    m.anisotropy_strength = ext_number(it->second, "anisotropyStrength", 0.0, ep);
    if (!(m.anisotropy_strength >= 0.0 && m.anisotropy_strength <= 1.0))
        fail(DR_ERR_FORMAT, "%s/anisotropyStrength: must be in [0, 1] (got %g)", ep.c_str(), m.anisotropy_strength);
    m.anisotropy_rotation = ext_number(it->second, "anisotropyRotation", 0.0, ep);
    if (!std::isfinite(m.anisotropy_rotation))
        fail(DR_ERR_FORMAT, "%s/anisotropyRotation: must be finite", ep.c_str());
    if (m.thin_ior > 0.0) {
        warn_once("thin:anisotropy", "%s: ignored on thin-walled glass (its reflection is the sheet's own)",
                  ep.c_str());
        m.anisotropy_strength = 0.0;
        return;
    }
    m.anisotropic = m.anisotropy_strength > 0.0;
    if (!m.anisotropic || !it->second.Has("anisotropyTexture")) return;
    const std::string tp = ep + "/anisotropyTexture";
    m.anisotropy_tex = texref(texture_info(it->second.Get("anisotropyTexture"), tp), tp);
    if (m.anisotropy_tex.texture >= 0) data_images_[size_t(scene_->textures[m.anisotropy_tex.texture].image)] = 1;
}

void Loader::load_material_medium(const tinygltf::Material &g, const std::string &mp, size_t index, dr_material &m)
{
    material_medium_.resize(index + 1, -1);
    bool has_vol = g.extensions.count("KHR_materials_volume") > 0;
    auto dr = g.extensions.find("DR_medium");
    if (!has_vol && dr == g.extensions.end()) {
        if (g.extensions.count("KHR_materials_transmission")) load_thin_glass(g, mp, m);
        return;
    }
    dr_medium med = empty_medium(g.name.empty() ? strf("material_%zu", index).c_str() : g.name.c_str(), int(index));
    if (has_vol) khr_volume(g, med);
    double ior = boundary_ior(g, mp, dr != g.extensions.end());
    med.ior = ior == 1.0 ? 0.0 : ior;   /* medium.h: 0 is index-matched */
    /* glTF's own volume (no DR_medium) on a mesh that turns out open: thin
     * glass instead of a refusal (dr_media_prepare) */
    med.thin_when_open = dr == g.extensions.end();
    media_.push_back(med);   /* owned (and released) by the loader from here */
    if (dr != g.extensions.end()) read_medium_ext(dr->second, mp + "/extensions/DR_medium", media_.back());
    material_medium_[index] = int(media_.size() - 1);
}

void Loader::load_global_medium()
{
    auto it = model_.extensions.find("DR_medium");
    if (it == model_.extensions.end()) return;
    const std::string ep = "/extensions/DR_medium";
    media_.push_back(empty_medium("global", -1));
    read_medium_ext(it->second, ep, media_.back());
    const dr_medium &m = media_.back();
    if (m.has_grid && !(m.grid.bmin.x < m.grid.bmax.x))
        fail(DR_ERR_FORMAT, "%s/bounds: a global medium with a density grid needs bounds {min, max}", ep.c_str());
}

void Loader::finish_media()
{
    if (media_.empty()) return;
    scene_->material_medium = static_cast<int *>(malloc(sizeof(int) * size_t(scene_->n_materials)));
    if (!scene_->material_medium) throw std::bad_alloc();
    scene_->global_medium = -1;
    for (int i = 0; i < scene_->n_materials; i++)
        scene_->material_medium[i] = size_t(i) < material_medium_.size() ? material_medium_[size_t(i)] : -1;
    for (size_t i = 0; i < media_.size(); i++)
        if (media_[i].material < 0) scene_->global_medium = int(i);
    scene_->media = copy_out(media_);
    if (!scene_->media) throw std::bad_alloc();
    scene_->n_media = int(media_.size());
    media_.clear();   /* the scene owns the grids now */
}

}  // namespace

extern "C" int dr_gltf_load(const char *path, struct dr_scene *scene)
{
    return dr_gltf_load_opts(path, nullptr, scene);
}

static int load(const char *path, const struct dr_load_opts *opts, struct dr_scene *scene, bool defer)
{
    dr_load_opts o = {};
    if (opts) o = *opts;
    try {
        Loader loader(path, o, scene, defer);
        loader.run();
        return 0;
    } catch (const Failure &f) {
        return f.code;
    } catch (const std::bad_alloc &) {
        dr_set_error("%s: out of memory", path);
        return DR_ERR_NOMEM;
    } catch (const std::exception &e) {
        dr_set_error("%s: internal error: %s", path, e.what());
        return DR_ERR_INTERNAL;
    } catch (...) {
        dr_set_error("%s: internal error", path);
        return DR_ERR_INTERNAL;
    }
}

extern "C" int dr_gltf_load_opts(const char *path, const struct dr_load_opts *opts, struct dr_scene *scene)
{
    return load(path, opts, scene, false);
}

extern "C" int dr_gltf_load_deferred(const char *path, const struct dr_load_opts *opts, struct dr_scene *scene)
{
    return load(path, opts, scene, true);
}

extern "C" int dr_pending_images_finish(struct dr_scene *scene)
{
    std::unique_ptr<dr_pending_images> p(scene->pending_images);
    scene->pending_images = nullptr;
    if (!p) return 0;
    try {
        p->thread.join();
        if (p->job_rc != 0) {
            dr_set_error("%s: out of memory", p->path.c_str());
            return p->job_rc;
        }
        const size_t failed = first_failure(p->encoded, p->rc);
        if (failed < p->rc.size()) {
            dr_set_error("%s: /images/%d: %s", p->path.c_str(), p->encoded[failed].index, p->why.at(failed));
            return p->rc[failed];
        }
        for (size_t k = 0; k < p->encoded.size(); k++) {
            dr_image &slot = scene->images[p->encoded[k].index];
            dr_image_release(&slot);
            slot = p->out[k];   /* the scene's now */
            p->out[k] = dr_image{};
        }
        return linearize_images(p->path.c_str(), scene->images, p->linear, p->data);
    } catch (const std::bad_alloc &) {
        dr_set_error("%s: out of memory", p->path.c_str());
        return DR_ERR_NOMEM;
    } catch (const std::exception &e) {
        dr_set_error("%s: internal error: %s", p->path.c_str(), e.what());
        return DR_ERR_INTERNAL;
    }
}

extern "C" void dr_pending_images_discard(struct dr_pending_images *pending)
{
    delete pending;
}
