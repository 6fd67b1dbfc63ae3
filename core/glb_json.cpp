/* The JSON chunk of a .glb, rewritten (see glb_json.h). */
#include "glb_json.h"

#include <cstddef>
#include <cstdint>
#include <cstring>

std::vector<unsigned char> dr_glb_rewrite_json(const std::vector<unsigned char> &glb, bool (*rewrite)(std::string &))
{
    auto u32 = [&](size_t at) {
        uint32_t v;
        memcpy(&v, glb.data() + at, 4);
        return v;
    };
    if (glb.size() < 20 || memcmp(glb.data(), "glTF", 4) != 0 || memcmp(glb.data() + 16, "JSON", 4) != 0) return {};
    size_t len = u32(12);
    if (len > glb.size() - 20) return {};
    std::string text(reinterpret_cast<const char *>(glb.data()) + 20, len);
    if (!rewrite(text)) return {};
    while (text.size() % 4) text.push_back(' ');   /* chunks are 4-byte aligned */
    std::vector<unsigned char> out(glb.begin(), glb.begin() + 12);
    uint32_t n = uint32_t(text.size());
    out.insert(out.end(), reinterpret_cast<unsigned char *>(&n), reinterpret_cast<unsigned char *>(&n) + 4);
    out.insert(out.end(), {'J', 'S', 'O', 'N'});
    out.insert(out.end(), text.begin(), text.end());
    out.insert(out.end(), glb.begin() + ptrdiff_t(20 + len), glb.end());
    uint32_t total = uint32_t(out.size());
    memcpy(out.data() + 8, &total, 4);
    return out;
}
