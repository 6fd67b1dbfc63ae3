/* Coverage of surfaces: alphaMode MASK/BLEND and back-face culling (coverage.h). */
#include "coverage.h"

#include "image.h"
#include "medium.h"   /* dr_fresnel_dielectric */

/* Salt of the thin-glass decision's uniform: apart from a BLEND decision on
 * the same triangle in the same query. */
#define THIN_SALT 0x7468696e676c6173ULL   /* "thinglas" */

double dr_thin_reflectance(double cos_i, double ior)
{
    double cos_t;
    const double F = dr_fresnel_dielectric(cos_i, ior, &cos_t);
    return 2.0 * F / (1.0 + F);
}

unsigned dr_material_coverage(const struct dr_scene *s, int m)
{
    if (m < 0 || m >= s->n_materials)
        return 0;
    const struct dr_material *mat = &s->materials[m];
    /* a medium boundary is crossed from both sides and lets light through
     * as it is (index-matched): never culled, never cut out */
    if (s->material_medium && m < s->n_materials && s->material_medium[m] >= 0)
        return 0;
    unsigned bits = mat->double_sided ? 0u : (unsigned)DR_COVER_CULL;
    if (mat->alpha_mode == DR_ALPHA_MASK)
        bits |= DR_COVER_MASK;
    else if (mat->alpha_mode == DR_ALPHA_BLEND)
        bits |= DR_COVER_BLEND;
    if (mat->thin_ior > 0.0)
        bits |= DR_COVER_THIN;
    return bits;
}

double dr_surface_alpha(const struct dr_scene *s, int64_t tri, double b1, double b2)
{
    const struct dr_mesh *m = &s->mesh;
    const struct dr_material *mat = &s->materials[m->material[tri]];
    double alpha = mat->alpha;
    const struct dr_texref *r = &mat->base_color_tex;
    if (r->texture < 0 || !(m->flags[tri] & DR_TRI_HAS_UVS))
        return alpha;   /* without UVs the texture is read at (0, 0), as dr_hit_compute's uv */
    const uint32_t *idx = m->indices + 3 * (size_t)tri;
    /* the texture's own TEXCOORD set and KHR_texture_transform, as dr_texref_uv */
    const float *uvs = r->texcoord == 1 && m->uvs1 ? m->uvs1 : m->uvs;
    const float *t0 = uvs + 2 * (size_t)idx[0], *t1 = uvs + 2 * (size_t)idx[1], *t2 = uvs + 2 * (size_t)idx[2];
    double b0 = 1.0 - b1 - b2;
    double u = b0 * t0[0] + b1 * t1[0] + b2 * t2[0], v = b0 * t0[1] + b1 * t1[1] + b2 * t2[1];
    if (r->transformed) {
        const double *x = r->xf;
        double tu = x[0] * u + x[1] * v + x[2];
        v = x[3] * u + x[4] * v + x[5];
        u = tu;
    }
    const struct dr_texture *t = &s->textures[r->texture];
    const struct dr_image *img = &s->images[t->image];
    double px[4];
    /* the linear copy keeps alpha as stored (only colour is sRGB-decoded) */
    dr_texture_eval(t, img, u, v, dr_image_has_linear(img), px);
    return alpha * px[3];
}

bool dr_coverage_point_present(const struct dr_scene *s, int64_t tri, double b1, double b2, uint64_t key)
{
    const struct dr_material *mat = &s->materials[s->mesh.material[tri]];
    if (mat->alpha_mode == DR_ALPHA_MASK)
        return dr_surface_alpha(s, tri, b1, b2) >= mat->alpha_cutoff;
    if (mat->alpha_mode == DR_ALPHA_BLEND)
        return dr_blend_uniform(key, tri) < dr_surface_alpha(s, tri, b1, b2);
    return true;
}

bool dr_coverage_blocks(const struct dr_scene *s, unsigned bits, int64_t tri, double b1, double b2, dr_vec3 d,
                        uint64_t key)
{
    if (bits & DR_COVER_CULL) {
        /* the same test as dr_hit_compute's "front", on the same double normal */
        const double *ng = s->mesh.tri_normal_eps + 4 * (size_t)tri;
        if (d.x * ng[0] + d.y * ng[1] + d.z * ng[2] >= 0.0)
            return false;
    }
    if ((bits & (DR_COVER_MASK | DR_COVER_BLEND)) && !dr_coverage_point_present(s, tri, b1, b2, key))
        return false;
    if (bits & DR_COVER_THIN) {
        const double *ng = s->mesh.tri_normal_eps + 4 * (size_t)tri;
        const double dn = d.x * ng[0] + d.y * ng[1] + d.z * ng[2], len = sqrt(dr_dot(d, d));
        const double R = dr_thin_reflectance(len > 0.0 ? fmin(fabs(dn) / len, 1.0) : 1.0,
                                             s->materials[s->mesh.material[tri]].thin_ior);
        return dr_blend_uniform(key ^ THIN_SALT, tri) < R;
    }
    return true;
}
