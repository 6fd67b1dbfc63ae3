// Diverging colour map for derivative pictures: a thin extern "C" shim over
// OpenImageIO 2.4's ImageBufAlgo::color_map. OIIO's named maps (inferno,
// viridis, magma, plasma, turbo, blue-red, spectrum, heat) have no diverging
// one with a neutral centre ("blue-red" passes through purple), so the map is
// given as knots: ColorBrewer RdBu (11 classes), reversed so that negative is
// blue. Nothing here throws across the C boundary.

#include "vis.h"
#include "image_plugin.h"

#include "error.h"
#include "image.h"

#include <OpenImageIO/imagebuf.h>
#include <OpenImageIO/imagebufalgo.h>

#include <cstring>
#include <exception>
#include <new>
#include <string>

using namespace OIIO;

namespace {

// ColorBrewer RdBu, 11 classes, from blue (negative) to red (positive), sRGB 8-bit.
const unsigned char rdbu_reversed[11][3] = {
    {0x05, 0x30, 0x61}, {0x21, 0x66, 0xac}, {0x43, 0x93, 0xc3}, {0x92, 0xc5, 0xde},
    {0xd1, 0xe5, 0xf0}, {0xf7, 0xf7, 0xf7}, {0xfd, 0xdb, 0xc7}, {0xf4, 0xa5, 0x82},
    {0xd6, 0x60, 0x4d}, {0xb2, 0x18, 0x2b}, {0x67, 0x00, 0x1f},
};

}  // namespace

extern "C" int drp_colormap_diverging(const float *t, int width, int height, float *rgb)
{
    try {
        float knots[11 * 3];
        for (int k = 0; k < 11; k++)
            for (int c = 0; c < 3; c++)
                knots[k * 3 + c] = (float)dr_srgb_to_linear(rdbu_reversed[k][c] / 255.0);
        ImageSpec spec(width, height, 1, TypeDesc::FLOAT);
        ImageBuf src(spec, const_cast<float *>(t));   // wraps the caller's buffer, no copy
        ImageBuf dst;
        if (!ImageBufAlgo::color_map(dst, src, 0, 11, 3, cspan<float>(knots, 11 * 3))) {
            std::string e = dst.geterror();
            dr_set_error("colour map: %s", e.empty() ? "OpenImageIO failed" : e.c_str());
            return DR_ERR_INTERNAL;
        }
        if (!dst.get_pixels(ROI(0, width, 0, height, 0, 1, 0, 3), TypeDesc::FLOAT, rgb)) {
            std::string e = dst.geterror();
            dr_set_error("colour map: %s", e.empty() ? "OpenImageIO failed" : e.c_str());
            return DR_ERR_INTERNAL;
        }
        return 0;
    } catch (const std::bad_alloc &) {
        dr_set_error("out of memory");
        return DR_ERR_NOMEM;
    } catch (const std::exception &ex) {
        dr_set_error("colour map: %s", ex.what());
        return DR_ERR_INTERNAL;
    } catch (...) {
        dr_set_error("colour map: unknown error");
        return DR_ERR_INTERNAL;
    }
}
