#include "sampler.h"

#include <string.h>

const char *dr_sampler_kind_name(enum dr_sampler_kind k)
{
    return k == DR_SAMPLER_SOBOL ? "sobol" : k == DR_SAMPLER_STRATIFIED ? "stratified" : "independent";
}

int dr_sampler_kind_parse(const char *name)
{
    if (strcmp(name, "independent") == 0)
        return DR_SAMPLER_INDEPENDENT;
    if (strcmp(name, "sobol") == 0)
        return DR_SAMPLER_SOBOL;
    if (strcmp(name, "stratified") == 0)
        return DR_SAMPLER_STRATIFIED;
    return -1;
}

/* dr_sobol_dim1's columns summed for each value of each four-bit group of
 * the index (generated from the column recurrence; test_sampler checks it). */
const uint32_t dr_sobol_dim1_nibble[8][16] = {
    {0x00000000u, 0x80000000u, 0xc0000000u, 0x40000000u, 0xa0000000u, 0x20000000u, 0x60000000u, 0xe0000000u,
     0xf0000000u, 0x70000000u, 0x30000000u, 0xb0000000u, 0x50000000u, 0xd0000000u, 0x90000000u, 0x10000000u},
    {0x00000000u, 0x88000000u, 0xcc000000u, 0x44000000u, 0xaa000000u, 0x22000000u, 0x66000000u, 0xee000000u,
     0xff000000u, 0x77000000u, 0x33000000u, 0xbb000000u, 0x55000000u, 0xdd000000u, 0x99000000u, 0x11000000u},
    {0x00000000u, 0x80800000u, 0xc0c00000u, 0x40400000u, 0xa0a00000u, 0x20200000u, 0x60600000u, 0xe0e00000u,
     0xf0f00000u, 0x70700000u, 0x30300000u, 0xb0b00000u, 0x50500000u, 0xd0d00000u, 0x90900000u, 0x10100000u},
    {0x00000000u, 0x88880000u, 0xcccc0000u, 0x44440000u, 0xaaaa0000u, 0x22220000u, 0x66660000u, 0xeeee0000u,
     0xffff0000u, 0x77770000u, 0x33330000u, 0xbbbb0000u, 0x55550000u, 0xdddd0000u, 0x99990000u, 0x11110000u},
    {0x00000000u, 0x80008000u, 0xc000c000u, 0x40004000u, 0xa000a000u, 0x20002000u, 0x60006000u, 0xe000e000u,
     0xf000f000u, 0x70007000u, 0x30003000u, 0xb000b000u, 0x50005000u, 0xd000d000u, 0x90009000u, 0x10001000u},
    {0x00000000u, 0x88008800u, 0xcc00cc00u, 0x44004400u, 0xaa00aa00u, 0x22002200u, 0x66006600u, 0xee00ee00u,
     0xff00ff00u, 0x77007700u, 0x33003300u, 0xbb00bb00u, 0x55005500u, 0xdd00dd00u, 0x99009900u, 0x11001100u},
    {0x00000000u, 0x80808080u, 0xc0c0c0c0u, 0x40404040u, 0xa0a0a0a0u, 0x20202020u, 0x60606060u, 0xe0e0e0e0u,
     0xf0f0f0f0u, 0x70707070u, 0x30303030u, 0xb0b0b0b0u, 0x50505050u, 0xd0d0d0d0u, 0x90909090u, 0x10101010u},
    {0x00000000u, 0x88888888u, 0xccccccccu, 0x44444444u, 0xaaaaaaaau, 0x22222222u, 0x66666666u, 0xeeeeeeeeu,
     0xffffffffu, 0x77777777u, 0x33333333u, 0xbbbbbbbbu, 0x55555555u, 0xddddddddu, 0x99999999u, 0x11111111u},
};

double dr_sampler_next_structured(struct dr_sampler *s)
{
    if (s->kind == DR_SAMPLER_SOBOL) {
        double u;
        dr_sampler_sobol2(s, ++s->dim, &u, NULL);
        return u;
    }
    ++s->dim;   /* DR_SAMPLER_STRATIFIED */
    return dr_strat_1d(s->index, s->count, (uint32_t)dr_sampler_strat_seed(s, s->dim),
                       dr_sampler_strat_jitter(s, s->dim, 0x3c6ef372fe94f82bULL));
}

/* dr_sampler_next2_structured's draw of dimensions d and d + 1, where h
 * holds dimension d's hashes (stratified: h->h alone). */
static void next2_hashed(struct dr_sampler *s, uint32_t d, const struct dr_sobol_hashes *h, double *u1, double *u2)
{
    s->dim = d + 1;
    if (s->kind == DR_SAMPLER_SOBOL) {
        dr_sobol2_hashed(h, s->index, u1, u2);
        return;
    }
    dr_strat_2d(s->index, s->grid_m, s->grid_n, h->h, dr_sampler_strat_jitter(s, d, 0x1ULL),   /* DR_SAMPLER_STRATIFIED */
                dr_sampler_strat_jitter(s, d, 0x2ULL), u1, u2);
}

void dr_sampler_next2_structured(struct dr_sampler *s, double *u1, double *u2)
{
    const uint32_t d = s->dim + 1;
    const uint64_t h = dr_sampler_dim_hash(s->pkey, d);
    struct dr_sobol_hashes hs = {h, 0, 0};
    if (s->kind == DR_SAMPLER_SOBOL)
        hs = dr_sobol_hashes_of(h);
    next2_hashed(s, d, &hs, u1, u2);
}

void dr_sampler_pixel_first2(const struct dr_sampler_pixel *p, struct dr_sampler *s, double *u1, double *u2)
{
    if (s->kind == DR_SAMPLER_INDEPENDENT)
        dr_sampler_next2(s, u1, u2);
    else
        next2_hashed(s, 1, &p->first, u1, u2);
}
