// Image reading and writing: a thin extern "C" shim over OpenImageIO 2.4.
//
// Nothing here throws across the C boundary: every exported function catches
// everything and turns it into a DR_ERR_* code with a message.
//
// Verified with OIIO 2.4.7 (Debian):
//  - ioproxy input is supported by the png, jpeg, hdr, openexr, tiff, bmp,
//    targa, gif and webp readers (fits is not); readers without it are fed
//    through a private temporary file instead.
//  - the built-in colour config knows "linear" and "sRGB", but an $OCIO
//    environment could rename them, so the 8-bit encoding uses our own exact
//    IEC 61966-2-1 curve (dr_linear_to_srgb) instead of colorconvert.
//  - the PNG/TGA plugins (de)associate alpha by default; we ask for
//    "oiio:UnassociatedAlpha" on both sides so values round-trip as given.

#include "image_io.h"
#include "image_plugin.h"

#include "bmp_check.h"
#include "cut_short.h"
#include "error.h"
#include "image.h"
#include "source_date.h"
#include "unsafe_images.h"

#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imageio.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <climits>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <new>
#include <string>
#include <vector>

#include <dirent.h>
#include <fcntl.h>
#include <strings.h>
#include <sys/stat.h>
#include <unistd.h>

using namespace OIIO;

namespace {

// The limit of dr_image_set_max_bytes; until it is called, the physical memory.
std::atomic<unsigned long long> g_max_image_bytes{0};
std::atomic<bool> g_max_image_set{false};

unsigned long long max_image_bytes()
{
    if (!g_max_image_set.load()) {
        long pages = sysconf(_SC_PHYS_PAGES), page = sysconf(_SC_PAGESIZE);
        return pages > 0 && page > 0 ? (unsigned long long)pages * (unsigned long long)page : 0;
    }
    return g_max_image_bytes.load();
}

// Would an image of w x h with nch channels, needing `need` bytes decoded,
// exceed the memory drender may use? Then the message says so (true).
bool over_limit(const std::string &label, int w, int h, int nch, double need)
{
    const unsigned long long limit = max_image_bytes();
    if (limit == 0 || need <= (double)limit)
        return false;
    dr_set_error("%s: cannot read image: %dx%d with %d channels needs %.1f MiB decoded, more than the "
                 "%.1f MiB of memory drender may use",
                 label.c_str(), w, h, nch, need / 1048576.0, (double)limit / 1048576.0);
    return true;
}

// One line, no trailing newline: OIIO messages sometimes end with '\n'.
std::string clean(std::string s)
{
    while (!s.empty() && (s.back() == '\n' || s.back() == '\r' || s.back() == ' '))
        s.pop_back();
    for (char &c : s)
        if (c == '\n')
            c = ' ';
    return s.empty() ? std::string("unknown error") : s;
}

std::string oiio_error(const ImageInput *in)
{
    std::string e = in ? in->geterror() : std::string();
    if (e.empty())
        e = OIIO::geterror();
    return clean(e);
}

std::string oiio_error(const ImageOutput *out)
{
    std::string e = out ? out->geterror() : std::string();
    if (e.empty())
        e = OIIO::geterror();
    return clean(e);
}

void zero_image(dr_image *img)
{
    *img = dr_image{};   // (every field: no pixels, no eight-bit storage)
}

// Extension of the last path component, without the dot; "" when none.
std::string extension_of(const std::string &path)
{
    size_t slash = path.find_last_of('/');
    size_t start = slash == std::string::npos ? 0 : slash + 1;
    size_t dot = path.find_last_of('.');
    if (dot == std::string::npos || dot < start || dot + 1 >= path.size())
        return std::string();
    // ".hidden" has no extension
    if (dot == start)
        return std::string();
    return path.substr(dot + 1);
}

bool starts_with_ci(const std::string &s, const char *prefix)
{
    size_t n = std::strlen(prefix);
    return s.size() >= n && strncasecmp(s.c_str(), prefix, n) == 0;
}

// Does the file declare sRGB-encoded values?
bool spec_is_srgb(const ImageSpec &spec, const char *format_name)
{
    std::string cs = spec.get_string_attribute("oiio:ColorSpace");
    if (starts_with_ci(cs, "srgb"))
        return true;
    if (starts_with_ci(cs, "linear") || starts_with_ci(cs, "lin_") ||
        starts_with_ci(cs, "scene_linear") || starts_with_ci(cs, "acescg"))
        return false;
    // No (or an unrecognised, e.g. "Gamma2.2") declaration: 8-bit files of
    // the display-referred formats are sRGB by convention.
    if (spec.format != TypeDesc::UINT8 || !format_name)
        return false;
    static const char *const srgb_formats[] = {"png", "jpeg", "bmp", "gif", "targa"};
    for (const char *f : srgb_formats)
        if (std::strcmp(format_name, f) == 0)
            return true;
    return false;
}

// An 8-bit file's pixels as bytes, in dr_image's eight-bit storage
// (image.h): each level's float is what OpenImageIO gives when it reads the
// file as float (the same conversion, asked for the 256 levels), so no float
// copy of the image is ever made. test_image compares the two reads.
int read_opened_bytes(ImageInput *in, const std::string &label, int nch, dr_image *img)
{
    const ImageSpec &spec = in->spec();
    const size_t n = (size_t)spec.width * (size_t)spec.height * (size_t)nch;
    uint8_t *bytes = (uint8_t *)dr_alloc_big(n);
    float *lut = (float *)std::malloc(512 * sizeof(float));   // (the second half: decoded, image.c)
    if (!bytes || !lut) {
        std::free(bytes);
        std::free(lut);
        dr_set_error("%s: cannot read image: out of memory", label.c_str());
        return DR_ERR_NOMEM;
    }
    unsigned char levels[256];
    for (int k = 0; k < 256; k++)
        levels[k] = (unsigned char)k;
    if (!in->read_image(0, 0, 0, nch, TypeDesc::UINT8, bytes) ||
        !convert_pixel_values(TypeDesc::UINT8, levels, TypeDesc::FLOAT, lut, 256)) {
        std::free(bytes);
        std::free(lut);
        dr_set_error("%s: cannot read image: %s", label.c_str(), oiio_error(in).c_str());
        return DR_ERR_FORMAT;
    }
    *img = dr_image{};
    img->width = spec.width;
    img->height = spec.height;
    img->channels = nch;
    img->bytes = bytes;
    img->lut = lut;
    img->file_is_srgb = spec_is_srgb(spec, in->format_name());
    return DR_OK;
}

// Reads the first subimage of an open ImageInput into img. `label` names the
// image in messages. On failure img is left zeroed. eight_bit: an 8-bit
// file's pixels in eight-bit storage (read_opened_bytes), others as float.
int read_opened(ImageInput *in, const std::string &label, dr_image *img, bool eight_bit)
{
    if (const char *why = dr_unsafe_reader(in->format_name())) {   // (a format without magic bytes)
        dr_set_error("%s: cannot read image: %s", label.c_str(), why);
        return DR_ERR_FORMAT;
    }
    const ImageSpec &spec = in->spec();
    if (spec.width <= 0 || spec.height <= 0 || spec.nchannels <= 0) {
        dr_set_error("%s: cannot read image: empty image (%dx%d, %d channels)",
                     label.c_str(), spec.width, spec.height, spec.nchannels);
        return DR_ERR_FORMAT;
    }
    if (spec.depth > 1) {
        dr_set_error("%s: cannot read image: volume images are not supported", label.c_str());
        return DR_ERR_FORMAT;
    }
    int nch = spec.nchannels < 4 ? spec.nchannels : 4;
    size_t w = (size_t)spec.width, h = (size_t)spec.height;
    if (w > SIZE_MAX / sizeof(float) / 4 / h) {
        dr_set_error("%s: cannot read image: image too large", label.c_str());
        return DR_ERR_FORMAT;
    }
    // Data plus the linear copy a colour texture gets, plus the scratch buffer
    // OpenImageIO 2.4's read_image converts through: 256 scanlines in the
    // file's own format, however few the image has (a 55-byte BMP claiming a
    // width of 3.6 million made it allocate 2.7 GB). Refused from the header,
    // before the decoder or we allocate pixel memory. (Eight-bit storage: a
    // byte per value, and its decoded values in a table.)
    const bool as_bytes = eight_bit && spec.format == TypeDesc::UINT8;
    double need = (as_bytes ? 1.0 : 2.0 * sizeof(float)) * (double)w * (double)h * nch +
                  256.0 * (double)w * (double)spec.pixel_bytes(true);
    if (over_limit(label, spec.width, spec.height, nch, need))
        return DR_ERR_NOMEM;
    if (as_bytes)
        return read_opened_bytes(in, label, nch, img);
    float *data = (float *)dr_alloc_big(w * h * (size_t)nch * sizeof(float));
    if (!data) {
        dr_set_error("%s: cannot read image: out of memory", label.c_str());
        return DR_ERR_NOMEM;
    }
    if (!in->read_image(0, 0, 0, nch, TypeDesc::FLOAT, data)) {
        std::free(data);
        dr_set_error("%s: cannot read image: %s", label.c_str(), oiio_error(in).c_str());
        return DR_ERR_FORMAT;
    }
    *img = dr_image{};
    img->width = spec.width;
    img->height = spec.height;
    img->channels = nch;
    img->data = data;
    img->file_is_srgb = spec_is_srgb(spec, in->format_name());
    return DR_OK;
}

ImageSpec read_config()
{
    ImageSpec config;
    // Values as stored: no alpha association by the PNG/TGA readers.
    config.attribute("oiio:UnassociatedAlpha", 1);
    return config;
}

// OpenImageIO 2.4's GIF reader decodes the first frame into a canvas of the
// file's logical screen size (4 bytes a pixel) as it opens the file, before
// read_opened sees the header: a 1 KB file claiming 29702x15720 took 7 s
// and 1.9 GB there, whatever the memory limit (found by make fuzz). So a
// GIF's screen size is checked against the limit first, from its first ten
// bytes (any other content: DR_OK, left to the reader; the fuzzer found
// the version bytes are not checked: "GIF88a" opens as well).
int refuse_huge_gif(const unsigned char *b, size_t n, const std::string &label)
{
    if (n < 10 || std::memcmp(b, "GIF", 3) != 0)   // (giflib reads any "GIF" + 3 bytes: "GIF88a" too)
        return DR_OK;
    const int w = b[6] | b[7] << 8, h = b[8] | b[9] << 8;
    return over_limit(label, w, h, 4, 4.0 * (double)w * (double)h) ? DR_ERR_NOMEM : DR_OK;
}

int refuse_huge_gif_file(const char *path, const std::string &label)
{
    unsigned char head[10];
    FILE *f = std::fopen(path, "rb");
    if (!f)
        return DR_OK;   // (the reader says why)
    const size_t n = std::fread(head, 1, sizeof head, f);
    std::fclose(f);
    return refuse_huge_gif(head, n, label);
}

// What OpenImageIO 2.4's readers must not see (unsafe_images.h), from the
// bytes (a BMP's whole file: its pixels are checked against a short colour
// table). file_size: the whole file's length. DR_OK for anything else.
int refuse_unsafe_image(const unsigned char *b, size_t n, bool whole, const std::string &label,
                        uint64_t file_size)
{
    char why[256];
    if (dr_unsafe_image_check(b, n, whole, file_size, why, sizeof why) == 0)
        return DR_OK;
    dr_set_error("%s: cannot read image: %s", label.c_str(), why);
    return DR_ERR_FORMAT;
}

// The same for a file: read whole when it is a BMP of at most 256 MiB (a
// larger one: its headers alone); the others by their first 1024 bytes
// (a DPX's image header ends at byte 780).
int refuse_unsafe_image_file(const char *path, const std::string &label)
{
    FILE *f = std::fopen(path, "rb");
    if (!f)
        return DR_OK;   // (the reader says why)
    unsigned char head[1024];
    size_t n = std::fread(head, 1, sizeof head, f);
    int rc = DR_OK;
    struct stat st;
    const uint64_t size = fstat(fileno(f), &st) == 0 ? (uint64_t)st.st_size : n;
    if (!dr_bmp_magic(head, n)) {
        rc = refuse_unsafe_image(head, n, false, label, size);   // (not a BMP: IFF and DPX are still checked)
    } else if (size > sizeof head && size <= ((uint64_t)256 << 20)) {
        std::vector<unsigned char> all((size_t)size);
        std::rewind(f);
        n = std::fread(all.data(), 1, all.size(), f);
        rc = refuse_unsafe_image(all.data(), n, true, label, n);
    } else {
        rc = refuse_unsafe_image(head, n, n < sizeof head, label, size);
    }
    char why[256];
    if (rc == DR_OK && n == sizeof head && dr_unsafe_image_file_check(f, size, why, sizeof why) != 0) {
        dr_set_error("%s: cannot read image: %s", label.c_str(), why);   // (past the first bytes: seeking)
        rc = DR_ERR_FORMAT;
    }
    std::fclose(f);
    return rc;
}

int read_file(const char *path, const std::string &label, dr_image *img, bool eight_bit)
{
    int grc = refuse_huge_gif_file(path, label);
    if (grc == DR_OK)
        grc = refuse_unsafe_image_file(path, label);
    if (grc != DR_OK)
        return grc;
    ImageSpec config = read_config();
    auto in = ImageInput::open(path, &config);
    if (!in) {
        struct stat st;
        bool readable = stat(path, &st) == 0 && S_ISREG(st.st_mode) && access(path, R_OK) == 0;
        int code = readable ? DR_ERR_FORMAT : DR_ERR_IO;
        dr_set_error("%s: cannot read image: %s", label.c_str(), oiio_error(in.get()).c_str());
        return code;
    }
    int rc = read_opened(in.get(), label, img, eight_bit);
    in->close();
    return rc;
}

// Bytes in memory for a reader, read within their bounds. OpenImageIO 2.4's
// IOMemReader::pread compares offset + size with the buffer's size in
// size_t, so a negative offset (a reader seeking to a value from the file's
// header, unchecked) wraps around and reads before the buffer (make fuzz: a
// BMP with a data offset of -44, an ASan heap-buffer-overflow). Here a read
// outside the buffer gets no bytes, which the readers report as a short read.
class BoundedMemReader final : public Filesystem::IOMemReader {
public:
    using Filesystem::IOMemReader::IOMemReader;
    size_t pread(void *buf, size_t size, int64_t offset) override
    {
        const int64_t n = (int64_t)m_buf.size();
        if (offset < 0 || offset >= n || size == 0)
            return 0;
        size = std::min(size, (size_t)(n - offset));
        std::memcpy(buf, m_buf.data() + offset, size);
        return size;
    }
    size_t read(void *buf, size_t size) override
    {
        const size_t got = pread(buf, size, m_pos);
        m_pos += (int64_t)got;
        return got;
    }
};

// Picks a file name whose extension selects the decoder for `bytes`.
std::string memory_name(const unsigned char *b, size_t n, const std::string &hint)
{
    if (n >= 8 && std::memcmp(b, "\x89PNG\r\n\x1a\n", 8) == 0)
        return "embedded.png";
    if (n >= 3 && b[0] == 0xFF && b[1] == 0xD8 && b[2] == 0xFF)
        return "embedded.jpg";
    if (n >= 4 && b[0] == 0x76 && b[1] == 0x2F && b[2] == 0x31 && b[3] == 0x01)
        return "embedded.exr";
    if ((n >= 10 && std::memcmp(b, "#?RADIANCE", 10) == 0) ||
        (n >= 6 && std::memcmp(b, "#?RGBE", 6) == 0))
        return "embedded.hdr";
    std::string ext = extension_of(hint);
    if (!ext.empty())
        return "embedded." + ext;
    // Perhaps a MIME type such as "image/png".
    size_t slash = hint.find_last_of('/');
    if (slash != std::string::npos && slash + 1 < hint.size())
        return "embedded." + hint.substr(slash + 1);
    return std::string();
}

// Fallback for readers without ioproxy support: a private temporary file.
// OpenImageIO 2.4's ICO reader leaves its file open when open() fails (a
// 2-byte .ico: one descriptor a read; make fuzz ran out of them after 230k
// inputs). A temporary's name is ours alone, so a descriptor still open on
// it once the reader is gone was left by the reader: it is closed here.
void close_left_open(const char *path)
{
    char real[PATH_MAX];
    DIR *d = realpath(path, real) ? opendir("/proc/self/fd") : nullptr;
    if (!d)
        return;
    std::vector<int> left;
    for (struct dirent *e; (e = readdir(d)) != nullptr;) {
        char *end;
        const long fd = std::strtol(e->d_name, &end, 10);
        if (*end || end == e->d_name || fd == dirfd(d))
            continue;
        char link[64], target[PATH_MAX];
        std::snprintf(link, sizeof link, "/proc/self/fd/%ld", fd);
        const ssize_t n = readlink(link, target, sizeof target - 1);
        if (n <= 0)
            continue;
        target[n] = '\0';
        if (std::strcmp(target, real) == 0)
            left.push_back((int)fd);
    }
    closedir(d);
    for (int fd : left)
        close(fd);
}

int read_memory_via_file(const void *bytes, size_t size, const std::string &ext,
                         const std::string &label, dr_image *img, bool eight_bit)
{
    const char *tmpdir = std::getenv("TMPDIR");
    if (!tmpdir || !*tmpdir)
        tmpdir = "/tmp";
    std::string suffix = "." + ext;
    std::string templ = std::string(tmpdir) + "/drender-img-XXXXXX" + suffix;
    std::vector<char> name(templ.begin(), templ.end());
    name.push_back('\0');
    int fd = mkstemps(name.data(), (int)suffix.size());
    if (fd < 0) {
        dr_set_error("%s: cannot read image: cannot create a temporary file in %s: %s",
                     label.c_str(), tmpdir, std::strerror(errno));
        return DR_ERR_IO;
    }
    const unsigned char *p = (const unsigned char *)bytes;
    size_t left = size;
    while (left > 0) {
        ssize_t k = write(fd, p, left);
        if (k < 0 && errno == EINTR)
            continue;
        if (k <= 0) {
            int e = errno;
            close(fd);
            unlink(name.data());
            dr_set_error("%s: cannot read image: cannot write a temporary file: %s",
                         label.c_str(), std::strerror(e));
            return DR_ERR_IO;
        }
        p += k;
        left -= (size_t)k;
    }
    close(fd);
    int rc = read_file(name.data(), label, img, eight_bit);
    close_left_open(name.data());
    unlink(name.data());
    if (rc == DR_ERR_IO)   // the temporary exists: the content is at fault
        rc = DR_ERR_FORMAT;
    return rc;
}

int read_memory(const void *bytes, size_t size, const char *name_hint, dr_image *img, bool eight_bit)
{
    std::string label = name_hint && *name_hint ? name_hint : "<memory>";
    if (!bytes || size == 0) {
        dr_set_error("%s: cannot read image: no data", label.c_str());
        return DR_ERR_FORMAT;
    }
    int grc = refuse_huge_gif((const unsigned char *)bytes, size, label);
    if (grc == DR_OK)
        grc = refuse_unsafe_image((const unsigned char *)bytes, size, true, label, size);
    if (grc != DR_OK)
        return grc;
    std::string name = memory_name((const unsigned char *)bytes, size, label);
    std::string ext = extension_of(name);
    // Notes on OIIO 2.4: ImageInput::create("x.png") tries to open the file,
    // so the plugin is looked up by the bare extension; and
    // ImageInput::open(name, &config, &proxy) ignores the proxy when a config
    // is given, so the proxy is attached with set_ioproxy() before open().
    std::unique_ptr<ImageInput> in;
    if (!ext.empty())
        in = ImageInput::create(ext);
    if (!in) {
        OIIO::geterror();   // clear
        dr_set_error("%s: cannot read image: unknown image format", label.c_str());
        return DR_ERR_FORMAT;
    }
    if (!in->supports("ioproxy")) {
        in.reset();
        return read_memory_via_file(bytes, size, ext, label, img, eight_bit);
    }

    BoundedMemReader proxy(bytes, size);
    ImageSpec config = read_config();
    ImageSpec spec;
    int rc;
    if (!in->set_ioproxy(&proxy) || !in->open(name, spec, config)) {
        dr_set_error("%s: cannot read image: %s", label.c_str(), oiio_error(in.get()).c_str());
        rc = DR_ERR_FORMAT;
    } else {
        rc = read_opened(in.get(), label, img, eight_bit);
        in->close();
    }
    in.reset();   // the input is gone before the proxy
    return rc;
}

// Formats that keep linear float values; everything else gets sRGB 8-bit.
bool is_float_format(const char *format_name)
{
    static const char *const float_formats[] = {"openexr", "hdr", "tiff", "fits", "pfm"};
    for (const char *f : float_formats)
        if (std::strcmp(format_name, f) == 0)
            return true;
    return false;
}

std::string dir_and_temp_name(const std::string &path, const std::string &ext)
{
    size_t slash = path.find_last_of('/');
    std::string dir = slash == std::string::npos ? std::string() : path.substr(0, slash + 1);
    std::string base = slash == std::string::npos ? path : path.substr(slash + 1);
    return dir + "." + base + ".tmp" + std::to_string((long)getpid()) + "." + ext;
}

// Removes the temporary output file unless told to keep it (also when an
// exception unwinds through write_image).
struct temp_guard {
    std::string path;
    bool keep = false;
    ~temp_guard()
    {
        if (!keep && !path.empty())
            unlink(path.c_str());   // unlink, not remove: never delete a directory
    }
};

inline uint8_t quantize(double v)
{
    if (!(v > 0.0))   // also NaN
        return 0;
    if (v >= 1.0)
        return 255;
    return (uint8_t)(v * 255.0 + 0.5);
}

// The file's channels: src_of[k] is the source channel of file channel k;
// alpha_k the file's alpha channel (-1: none).
struct file_layout {
    int out_ch;
    int src_of[4];
    int alpha_k;
};

file_layout layout_for(const char *fmt, ImageOutput *out, int channels)
{
    file_layout l;
    const bool has_alpha = channels == 2 || channels == 4;
    if (std::strcmp(fmt, "hdr") == 0) {   // RGBE: exactly RGB
        l.out_ch = 3;
        for (int k = 0; k < 3; ++k)
            l.src_of[k] = channels >= 3 ? k : 0;
    } else if (has_alpha && !out->supports("alpha")) {   // JPEG, PNM, ...: drop alpha
        l.out_ch = channels - 1;
        for (int k = 0; k < l.out_ch; ++k)
            l.src_of[k] = k;
    } else {
        l.out_ch = channels;
        for (int k = 0; k < l.out_ch; ++k)
            l.src_of[k] = k;
    }
    l.alpha_k = (has_alpha && l.out_ch == channels) ? l.out_ch - 1 : -1;
    return l;
}

// The pixels as the file stores them: linear floats (as_float), or bytes,
// sRGB-encoded but for alpha when srgb_encode. Data written as-is gets no
// colour-space tag (no sRGB/gAMA chunk): glTF reads such textures
// (metallic-roughness) as linear regardless.
void file_pixels(const file_layout &l, size_t n, int channels, const float *pixels, bool as_float, bool srgb_encode,
                 ImageSpec &spec, std::vector<float> &fbuf, std::vector<uint8_t> &bbuf)
{
    const int out_ch = l.out_ch;
    if (as_float) {
        fbuf.resize(n * (size_t)out_ch);
        for (size_t i = 0; i < n; ++i)
            for (int k = 0; k < out_ch; ++k)
                fbuf[i * out_ch + k] = pixels[i * channels + l.src_of[k]];
        return;
    }
    if (srgb_encode)
        spec.attribute("oiio:ColorSpace", "sRGB");
    bbuf.resize(n * (size_t)out_ch);
    for (size_t i = 0; i < n; ++i)
        for (int k = 0; k < out_ch; ++k) {
            double v = pixels[i * channels + l.src_of[k]];
            if (k != l.alpha_k && srgb_encode)
                v = dr_linear_to_srgb(v > 0.0 ? v : 0.0);
            bbuf[i * out_ch + k] = quantize(v);
        }
}

// Writes bytes to a new file at path, checking every write and the close:
// 0, or the errno of what failed.
int write_file_checked(const std::string &path, const std::vector<unsigned char> &bytes)
{
    int fd = open(path.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0666);
    if (fd < 0)
        return errno;
    const unsigned char *p = bytes.data();
    size_t left = bytes.size();
    while (left > 0) {
        ssize_t k = ::write(fd, p, left);
        if (k < 0 && errno == EINTR)
            continue;
        if (k <= 0) {
            int e = k < 0 ? errno : EIO;
            close(fd);
            return e;
        }
        p += k;
        left -= (size_t)k;
    }
    // (on disk before the rename that follows, as checkpoints and glTF
    // outputs are: a machine that stops after it must not leave an empty
    // file under the output's name; some filesystems report a full disk
    // only here)
    if (fsync(fd) != 0) {
        int e = errno;
        close(fd);
        return e;
    }
    return close(fd) != 0 ? errno : 0;
}

// fsync of a file another writer (OpenImageIO's plugin) wrote: 0 or errno.
int fsync_path(const std::string &path)
{
    int fd = open(path.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd < 0)
        return errno;
    int e = fsync(fd) != 0 ? errno : 0;
    close(fd);
    return e;
}

// For the formats that take no proxy (sgi, ico, fits, rla, heif): the file
// is read back whole, so that a write the plugin did not check cannot pass.
bool reads_back(const std::string &tmp, std::string &why)
{
    auto in = ImageInput::open(tmp);
    std::vector<float> px;
    bool ok = (bool)in;
    if (ok) {
        const ImageSpec &sp = in->spec();
        px.resize((size_t)sp.width * sp.height * sp.nchannels);
        ok = in->read_image(0, 0, 0, sp.nchannels, TypeDesc::FLOAT, px.data());
    }
    if (!ok)
        why = in ? oiio_error(in.get()) : clean(OIIO::geterror());
    return ok;
}

// Writes data to a temporary beside path and renames it over path, so that a
// failed write leaves nothing half-written under path's name. Closes out.
//
// The formats that take a proxy (png, exr, jpeg, tiff, hdr and most others)
// are encoded into memory and then written by write_file_checked: OpenImageIO's
// writers do not all check their writes. Its PNG writer ignored a short
// fwrite (a full disk left a cut-short PNG under the output's name, and exit
// 0), and libjpeg ends the process on one ("Output file write error", exit 1,
// the temporary left behind). The encoded copy costs the file's size in
// memory for the moment of the write.
int write_then_rename(std::unique_ptr<ImageOutput> &out, const std::string &spath, const ImageSpec &spec,
                      TypeDesc type, const void *data)
{
    const char *path = spath.c_str();
    std::string tmp = dir_and_temp_name(spath, extension_of(spath));
    temp_guard guard;
    guard.path = tmp;
    std::string why;
    std::vector<unsigned char> bytes;
    Filesystem::IOVecOutput memory(bytes);
    const bool proxied = out->supports("ioproxy");
    bool ok = true;
    if (proxied && !out->set_ioproxy(&memory))
        ok = false, why = oiio_error(out.get());
    else if (!out->open(tmp, spec))
        ok = false, why = oiio_error(out.get());
    if (ok && !out->write_image(type, data))
        ok = false, why = oiio_error(out.get());
    if (!out->close() && ok)
        ok = false, why = oiio_error(out.get());
    out.reset();   // (before the proxy it may hold goes)
    if (ok && proxied) {
        int e = write_file_checked(tmp, bytes);
        if (e)
            ok = false, why = std::strerror(e);
    } else if (ok && !reads_back(tmp, why)) {
        char cause[256];   // (the plugin's own writes report nothing: the likely cause)
        why = std::string(dr_why_cut_short(tmp.c_str(), cause, sizeof cause)) + " (reading it back: " + why + ")";
        ok = false;
    } else if (ok) {
        int e = fsync_path(tmp);
        if (e)
            ok = false, why = std::strerror(e);
    }
    if (ok && std::rename(tmp.c_str(), path) != 0) {
        ok = false;
        why = std::strerror(errno);
    }
    if (!ok) {
        // OpenImageIO's message names the temporary; the user knows only path.
        for (size_t at; (at = why.find(tmp)) != std::string::npos;)
            why.replace(at, tmp.size(), path);
        dr_set_error("%s: cannot write image: %s", path, why.c_str());
        return DR_ERR_IO;   // the guard removes the temporary
    }
    guard.keep = true;   // renamed: nothing left to remove
    return DR_OK;
}

// Is at least half of v exactly zero? A texture's gradient is (the texels
// no path read), and for such an image OpenEXR's run-length encoding beats
// OpenImageIO's default, zip: a 2k texture's gradient of 16 spp at 128 x 128
// (half its values 0) took 1.12 s to write with zip, 24.0 MB, and 0.18 s
// with RLE, 26.5 MB, while the gradient itself took about 1 s. Images of
// dense noise compress little either way (a render: zip 11.5 MB in 0.40 s,
// RLE 11.9 MB in 0.05 s), but smooth synthetic ones only with zip, so the
// rest keep it.
bool mostly_zero(const float *v, size_t n)
{
    size_t zeros = 0;
    for (size_t i = 0; i < n; ++i)
        zeros += v[i] == 0.0f;
    return 2 * zeros >= n;
}

// Whether a float file takes the caller's pixels as they are (every channel,
// in order): then they are written from where they are. A copy of a 2k
// texture's gradient image was 50 MB of fresh pages faulted in, zeroed and
// filled before the write.
bool identity_layout(const file_layout &l, int channels)
{
    if (l.out_ch != channels)
        return false;
    for (int k = 0; k < l.out_ch; ++k)
        if (l.src_of[k] != k)
            return false;
    return true;
}

int write_image(const char *path, int width, int height, int channels, const float *pixels,
                bool srgb_encode)
{
    std::string spath = path;
    auto out = ImageOutput::create(spath);
    if (!out) {
        OIIO::geterror();   // clear
        dr_set_error("%s: OpenImageIO cannot write this format", path);
        return DR_ERR_ARG;
    }
    if (width <= 0 || height <= 0 || channels < 1 || channels > 4 || !pixels) {
        dr_set_error("%s: cannot write image: invalid image (%dx%d, %d channels)", path, width,
                     height, channels);
        return DR_ERR_ARG;
    }
    const char *fmt = out->format_name();
    const bool as_float = is_float_format(fmt);
    const file_layout l = layout_for(fmt, out.get(), channels);
    ImageSpec spec(width, height, l.out_ch, as_float ? TypeDesc::FLOAT : TypeDesc::UINT8);
    if (l.alpha_k >= 0)
        spec.alpha_channel = l.alpha_k;
    if (l.out_ch == 2) {
        spec.channelnames = {"Y", "A"};
    } else if (l.out_ch == 1) {
        spec.channelnames = {"Y"};
    }
    spec.attribute("oiio:UnassociatedAlpha", 1);
    char stamp[32];   /* (EXR and TIFF writers stamp the time: without this, now) */
    if (dr_source_date_string(stamp, sizeof stamp))
        spec.attribute("DateTime", stamp);
    std::vector<float> fbuf;
    std::vector<uint8_t> bbuf;
    const size_t n = (size_t)width * (size_t)height;
    const bool as_given = as_float && identity_layout(l, channels);
    if (!as_given)
        file_pixels(l, n, channels, pixels, as_float, srgb_encode, spec, fbuf, bbuf);
    const float *fdata = as_given ? pixels : fbuf.data();
    if (as_float && std::strcmp(fmt, "openexr") == 0 && mostly_zero(fdata, n * (size_t)l.out_ch))
        spec.attribute("compression", "rle");
    return as_float ? write_then_rename(out, spath, spec, TypeDesc::FLOAT, fdata)
                    : write_then_rename(out, spath, spec, TypeDesc::UINT8, bbuf.data());
}


// ---- volumes (OpenVDB through OpenImageIO's openvdb reader) ----
//
// Verified with OIIO 2.4.7 and OpenVDB 10 (Debian): every float grid is a
// subimage with one channel (vec3 grids: three), named by
// "oiio:subimagename"; the display ("full") window is the grid's active voxel
// bounding box in index coordinates, the data window its tile-aligned
// (8^3 leaf) cover, and voxel (i, j, k) of the data window is index
// coordinate (x + i, y + j, z + k), x fastest. A file with no float or vec3
// grid (only a bool grid, say) is not opened at all ("could not find a format
// reader"), so the file's magic number tells such a file from one that is not
// an OpenVDB file. An empty grid has a full window of 0 x 0 x 0.

// OpenVDB files begin with the 64-bit little-endian magic number 0x56444220.
bool has_vdb_magic(const char *path)
{
    static const unsigned char magic[8] = {0x20, 0x42, 0x44, 0x56, 0, 0, 0, 0};
    unsigned char head[8] = {0};
    FILE *f = std::fopen(path, "rb");
    if (!f)
        return false;
    size_t n = std::fread(head, 1, sizeof head, f);
    std::fclose(f);
    return n == sizeof head && std::memcmp(head, magic, sizeof head) == 0;
}

// The float grids of an open volume file, as (subimage, name); also every
// grid's name, for messages.
struct volume_grids {
    std::vector<std::pair<int, std::string>> floats;
    std::string all;
};

volume_grids list_grids(ImageInput *in)
{
    volume_grids g;
    for (int si = 0; in->seek_subimage(si, 0); si++) {
        const ImageSpec &s = in->spec();
        std::string name = s.get_string_attribute("oiio:subimagename");
        if (name.empty())
            name = "#" + std::to_string(si);
        g.all += (g.all.empty() ? "" : ", ") + name + (s.nchannels == 1 ? "" : " (vec3)");
        if (s.nchannels == 1)
            g.floats.emplace_back(si, name);
    }
    OIIO::geterror();   // seeking past the last subimage leaves an error
    return g;
}

// Picks the subimage to read; -1 with the message set when there is none.
int pick_grid(ImageInput *in, const char *path, const char *want)
{
    volume_grids g = list_grids(in);
    bool named = want && *want;
    for (const auto &f : g.floats)
        if (f.second == (named ? want : "density"))
            return f.first;
    if (named) {
        dr_set_error("%s: cannot read volume: no float grid named '%s' (the file has: %s)", path, want,
                     g.all.c_str());
        return -1;
    }
    if (g.floats.empty()) {
        dr_set_error("%s: cannot read volume: no float grid (the file has: %s)", path, g.all.c_str());
        return -1;
    }
    return g.floats[0].first;
}

// Refuses from the header what the voxel or memory limits do not allow.
int check_volume_size(const ImageSpec &s, const char *path, const std::string &name)
{
    double box = (double)s.full_width * s.full_height * s.full_depth;
    if (box > (double)DR_VOLUME_MAX_VOXELS) {
        dr_set_error("%s: cannot read volume: grid '%s' has an active bounding box of %dx%dx%d voxels, more "
                     "than the 2^28 supported", path, name.c_str(), s.full_width, s.full_height, s.full_depth);
        return DR_ERR_FORMAT;
    }
    // The reader's tile-aligned buffer, our copy of the box, and the grids
    // OpenVDB holds in memory while the file is open.
    double tiles = (double)s.width * s.height * (s.depth > 0 ? s.depth : 1) * s.nchannels * sizeof(float);
    int64_t held = 0;   // an int64 attribute: get_int_attribute would truncate past 2 GiB
    if (!s.getattribute("openvdb:file_mem_bytes", TypeDesc::INT64, &held))
        held = 0;
    double need = tiles + box * sizeof(float) + (double)held;
    unsigned long long limit = max_image_bytes();
    if (limit > 0 && need > (double)limit) {
        dr_set_error("%s: cannot read volume: grid '%s' (%dx%dx%d active box, %dx%dx%d in tiles) needs %.1f MiB "
                     "decoded, more than the %.1f MiB of memory drender may use", path, name.c_str(),
                     s.full_width, s.full_height, s.full_depth, s.width, s.height, s.depth, need / 1048576.0,
                     (double)limit / 1048576.0);
        return DR_ERR_NOMEM;
    }
    return DR_OK;
}

// Reads subimage si (one channel) and copies its display window into vol.
int read_volume_box(ImageInput *in, int si, const char *path, dr_volume *vol)
{
    const ImageSpec s = in->spec();
    std::string name = s.get_string_attribute("oiio:subimagename");
    if (s.full_width <= 0 || s.full_height <= 0 || s.full_depth <= 0) {
        dr_set_error("%s: cannot read volume: grid '%s' has no active voxels", path, name.c_str());
        return DR_ERR_FORMAT;
    }
    if (s.full_x < s.x || s.full_y < s.y || s.full_z < s.z || s.full_x + s.full_width > s.x + s.width ||
        s.full_y + s.full_height > s.y + s.height || s.full_z + s.full_depth > s.z + s.depth) {
        dr_set_error("%s: cannot read volume: grid '%s': the active box lies outside the reader's data window",
                     path, name.c_str());
        return DR_ERR_FORMAT;
    }
    int rc = check_volume_size(s, path, name);
    if (rc != DR_OK)
        return rc;
    std::vector<float> tiles((size_t)s.width * s.height * s.depth);
    if (!in->read_image(si, 0, 0, 1, TypeDesc::FLOAT, tiles.data())) {
        dr_set_error("%s: cannot read volume: grid '%s': %s", path, name.c_str(), oiio_error(in).c_str());
        return DR_ERR_FORMAT;
    }
    size_t nx = (size_t)s.full_width, ny = (size_t)s.full_height, nz = (size_t)s.full_depth;
    float *data = (float *)std::malloc(nx * ny * nz * sizeof(float));
    if (!data) {
        dr_set_error("%s: cannot read volume: out of memory", path);
        return DR_ERR_NOMEM;
    }
    for (size_t z = 0; z < nz; z++)
        for (size_t y = 0; y < ny; y++) {
            size_t from = (((size_t)(s.full_z - s.z) + z) * s.height + (size_t)(s.full_y - s.y) + y) * s.width +
                          (size_t)(s.full_x - s.x);
            std::memcpy(data + (z * ny + y) * nx, tiles.data() + from, nx * sizeof(float));
        }
    vol->nx = s.full_width;
    vol->ny = s.full_height;
    vol->nz = s.full_depth;
    vol->x0 = s.full_x;
    vol->y0 = s.full_y;
    vol->z0 = s.full_z;
    vol->data = data;
    std::snprintf(vol->grid, sizeof vol->grid, "%s", name.c_str());
    return DR_OK;
}

int read_volume(const char *path, const char *grid, dr_volume *vol)
{
    struct stat st;
    if (stat(path, &st) != 0 || access(path, R_OK) != 0) {
        dr_set_error("%s: cannot read volume: %s", path, std::strerror(errno));
        return DR_ERR_IO;
    }
    if (!S_ISREG(st.st_mode)) {
        dr_set_error("%s: cannot read volume: not a regular file", path);
        return DR_ERR_IO;
    }
    if (!has_vdb_magic(path)) {
        dr_set_error("%s: cannot read volume: not an OpenVDB file", path);
        return DR_ERR_FORMAT;
    }
    auto in = ImageInput::open(path);
    if (!in || std::strcmp(in->format_name(), "openvdb") != 0) {
        // OpenImageIO opens only VDB files that have a float or vec3 grid
        OIIO::geterror();   // clear: its "no format reader" would mislead
        dr_set_error("%s: cannot read volume: no float grid (OpenImageIO's openvdb reader finds no float or vec3 "
                     "grid in it)", path);
        return DR_ERR_FORMAT;
    }
    int si = pick_grid(in.get(), path, grid);
    int rc = DR_ERR_FORMAT;
    if (si >= 0 && !in->seek_subimage(si, 0))
        dr_set_error("%s: cannot read volume: %s", path, oiio_error(in.get()).c_str());
    else if (si >= 0)
        rc = read_volume_box(in.get(), si, path, vol);
    in->close();
    return rc;
}
}   // namespace

static int plugin_read(const char *path, struct dr_image *img)
{
    if (!img)
        return DR_ERR_ARG;
    zero_image(img);
    if (!path || !*path) {
        dr_set_error("cannot read image: empty file name");
        return DR_ERR_ARG;
    }
    try {
        return read_file(path, path, img, false);
    } catch (const std::bad_alloc &) {
        dr_image_release(img);
        zero_image(img);
        dr_set_error("%s: cannot read image: out of memory", path);
        return DR_ERR_NOMEM;
    } catch (const std::exception &e) {
        dr_image_release(img);
        zero_image(img);
        dr_set_error("%s: cannot read image: %s", path, e.what());
        return DR_ERR_INTERNAL;
    } catch (...) {
        dr_image_release(img);
        zero_image(img);
        dr_set_error("%s: cannot read image: unexpected error", path);
        return DR_ERR_INTERNAL;
    }
}

// dr_image_read_memory and dr_image_read_memory8 (eight_bit).
static int read_memory_caught(const void *bytes, size_t size, const char *name_hint, struct dr_image *img,
                              bool eight_bit)
{
    if (!img)
        return DR_ERR_ARG;
    zero_image(img);
    const char *label = name_hint && *name_hint ? name_hint : "<memory>";
    try {
        return read_memory(bytes, size, name_hint, img, eight_bit);
    } catch (const std::bad_alloc &) {
        dr_image_release(img);
        zero_image(img);
        dr_set_error("%s: cannot read image: out of memory", label);
        return DR_ERR_NOMEM;
    } catch (const std::exception &e) {
        dr_image_release(img);
        zero_image(img);
        dr_set_error("%s: cannot read image: %s", label, e.what());
        return DR_ERR_INTERNAL;
    } catch (...) {
        dr_image_release(img);
        zero_image(img);
        dr_set_error("%s: cannot read image: unexpected error", label);
        return DR_ERR_INTERNAL;
    }
}

static int plugin_read_memory(const void *bytes, size_t size, const char *name_hint, struct dr_image *img)
{
    return read_memory_caught(bytes, size, name_hint, img, false);
}

static int plugin_read_memory8(const void *bytes, size_t size, const char *name_hint, struct dr_image *img)
{
    return read_memory_caught(bytes, size, name_hint, img, true);
}

static void plugin_set_max_bytes(unsigned long long bytes)
{
    g_max_image_bytes.store(bytes);
    g_max_image_set.store(true);
}

/* OpenEXR's pool, which compresses an EXR's blocks on as many threads as
 * the machine has: 0 is its default, one per CPU; one thread is none
 * besides the caller (exr_threads -1). (OpenImageIO's own pool is not
 * used by drender's reads and writes; sizing it would start it.) */
static void plugin_set_threads(int n)
{
    OIIO::attribute("exr_threads", n == 1 ? -1 : (n > 0 ? n : 0));
}

static bool plugin_can_write(const char *path)
{
    if (!path || !*path)
        return false;
    try {
        bool ok = (bool)ImageOutput::create(std::string(path));
        if (!ok)
            OIIO::geterror();   // clear
        return ok;
    } catch (...) {
        return false;
    }
}

static int plugin_write_encoded(const char *path, int width, int height, int channels,
                                      const float *pixels, bool srgb_encode)
{
    if (!path || !*path) {
        dr_set_error("cannot write image: empty file name");
        return DR_ERR_ARG;
    }
    try {
        return write_image(path, width, height, channels, pixels, srgb_encode);
    } catch (const std::bad_alloc &) {
        dr_set_error("%s: cannot write image: out of memory", path);
        return DR_ERR_NOMEM;
    } catch (const std::exception &e) {
        dr_set_error("%s: cannot write image: %s", path, e.what());
        return DR_ERR_INTERNAL;
    } catch (...) {
        dr_set_error("%s: cannot write image: unexpected error", path);
        return DR_ERR_INTERNAL;
    }
}

static int plugin_read_volume(const char *path, const char *grid, struct dr_volume *vol)
{
    if (!vol)
        return DR_ERR_ARG;
    std::memset(vol, 0, sizeof *vol);
    if (!path || !*path) {
        dr_set_error("cannot read volume: empty file name");
        return DR_ERR_ARG;
    }
    try {
        return read_volume(path, grid, vol);
    } catch (const std::bad_alloc &) {
        dr_set_error("%s: cannot read volume: out of memory", path);
        return DR_ERR_NOMEM;
    } catch (const std::exception &e) {
        dr_set_error("%s: cannot read volume: %s", path, e.what());
        return DR_ERR_INTERNAL;
    } catch (...) {
        dr_set_error("%s: cannot read volume: unexpected error", path);
        return DR_ERR_INTERNAL;
    }
}

// The plugin's entry point: image_plugin.c finds this with dlsym (or, when
// this file is linked in directly, through a weak reference).
extern "C" const struct dr_image_plugin *dr_image_plugin_table(void)
{
    static const struct dr_image_plugin table = {
        DR_IMAGE_PLUGIN_VERSION, plugin_read,          plugin_read_memory,    plugin_set_max_bytes,
        plugin_can_write,        plugin_write_encoded, drp_colormap_diverging, plugin_read_volume,
        plugin_read_memory8,     plugin_set_threads,
    };
    return &table;
}
