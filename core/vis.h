/* Pictures of derivative images: a diverging blue-white-red colour map
 * (vis.cpp, a thin extern "C" shim over OpenImageIO's ImageBufAlgo::color_map). */
#ifndef DR_VIS_H
#define DR_VIS_H

#ifdef __cplusplus
extern "C" {
#endif

/* Maps t (width * height values in [0, 1]; 0 = most negative, 0.5 = zero,
 * 1 = most positive) to linear float RGB (width * height * 3) through
 * ColorBrewer's RdBu map reversed (dark blue, white, dark red), given to
 * color_map as knots. The knots are decoded from sRGB, so an sRGB-encoded
 * 8-bit file (dr_image_write to .png) shows ColorBrewer's colours.
 * 0 or a negative DR_ERR_* with dr_last_error set. */
int dr_colormap_diverging(const float *t, int width, int height, float *rgb);

#ifdef __cplusplus
}
#endif
#endif
