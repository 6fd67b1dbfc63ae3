/* Generates core/sheen_albedo.c: the directional albedo
 *   E(mu, r) = integral over the hemisphere of D(h) G(wo, wi) / (4 mu) dwi
 * of the Estevez-Kulla sheen lobe (core/bsdf_sheen.c's model, written out
 * again here from the paper's formulas) with a white colour, on the grid of
 * core/sheen_albedo.h. Built and run by `make sheen-table`; not part of the
 * normal build.
 *
 * Quadrature: in half-vector space, dwi = 4 (wo.h) dw_h, dw_h = dt dphi with
 * t = cos(theta_h). The lobe is sharp near t = 0 at small roughness
 * (D ~ (1 - t^2)^(1/(2 alpha)), width ~ sqrt(alpha) in t), so t is
 * integrated by adaptive Gauss-Kronrod (7/15) started on pieces that are
 * fine near 0; for each t the directions with wi.z > 0 are
 * |phi| < acos(mu (1 - 2 t^2) / (2 t sin_o sin_h)) (wi.z = 2 (wo.h) t - mu),
 * so phi is integrated over exactly that range, adaptively too (the
 * integrand's x^c terms make it steep at the range's end). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>

#include "../core/sheen_albedo.h"

static const double P_R0[5] = {25.3245, 3.32435, 0.16801, -1.27393, -4.85967};
static const double P_R1[5] = {21.5473, 3.82987, 0.19823, -1.97760, -4.32054};

struct lobe {
    double alpha, p[5], Lhalf;
};

static double Lfun(const struct lobe *l, double x)
{
    return l->p[0] / (1.0 + l->p[1] * pow(x, l->p[2])) + l->p[3] * x + l->p[4];
}

static double Lambda(const struct lobe *l, double x)
{
    return x < 0.5 ? exp(Lfun(l, x)) : exp(2.0 * l->Lhalf - Lfun(l, 1.0 - x));
}

static struct lobe make_lobe(double r)
{
    struct lobe l;
    l.alpha = r * r;
    double t = (1.0 - l.alpha) * (1.0 - l.alpha);
    for (int i = 0; i < 5; i++)
        l.p[i] = (1.0 - t) * P_R1[i] + t * P_R0[i];
    l.Lhalf = Lfun(&l, 0.5);
    return l;
}

typedef double (*fn1)(void *ctx, double x);

static const double XK[8] = {0.991455371120812639206854697526329, 0.949107912342758524526189684047851,
                             0.864864423359769072789712788640926, 0.741531185599394439863864773280788,
                             0.586087235467691130294144845693013, 0.405845151377397166906606412076961,
                             0.207784955007898467600689403773245, 0.0};
static const double WK[8] = {0.022935322010529224963732008058970, 0.063092092629978553290700663189204,
                             0.104790010322250183839876322541518, 0.140653259715525918745189590510238,
                             0.169004726639267902826583426598550, 0.190350578064785409913256402421014,
                             0.204432940075298892414161999234649, 0.209482141084727828012999174891714};
static const double WG[4] = {0.129484966168869693270611432679082, 0.279705391489276667901467771423780,
                             0.381830050505118944950369775488975, 0.417959183673469387755102040816327};

static double gk15(fn1 f, void *ctx, double a, double b, double *err)
{
    double c = 0.5 * (a + b), h = 0.5 * (b - a);
    double fc = f(ctx, c), rk = WK[7] * fc, rg = WG[3] * fc;
    for (int i = 0; i < 7; i++) {
        double x = h * XK[i], s = f(ctx, c - x) + f(ctx, c + x);
        rk += WK[i] * s;
        if (i % 2 == 1)
            rg += WG[i / 2] * s;
    }
    *err = fabs((rk - rg) * h);
    return rk * h;
}

static double adapt(fn1 f, void *ctx, double a, double b, double tol, int depth)
{
    double err, v = gk15(f, ctx, a, b, &err);
    if (err <= tol || depth > 30)
        return v;
    double c = 0.5 * (a + b);
    return adapt(f, ctx, a, c, 0.5 * tol, depth + 1) + adapt(f, ctx, c, b, 0.5 * tol, depth + 1);
}

struct ctx {
    const struct lobe *l;
    double mu, so;   /* wo = (so, 0, mu) */
    double t, sh;    /* the current half vector's cos and sin theta */
};

/* D G / (4 mu) * 4 (wo.h) at the current t and phi (per dt dphi). */
static double inner(void *vc, double phi)
{
    struct ctx *c = vc;
    double oh = c->so * c->sh * cos(phi) + c->mu * c->t;
    double wiz = 2.0 * oh * c->t - c->mu;
    if (!(wiz > 0.0) || !(oh > 0.0))
        return 0.0;
    const struct lobe *l = c->l;
    double inv = 1.0 / l->alpha;
    double D = (2.0 + inv) * pow(c->sh * c->sh, 0.5 * inv) / (2.0 * M_PI);
    double G = 1.0 / (1.0 + Lambda(l, c->mu) + Lambda(l, fmin(wiz, 1.0)));
    return D * G * oh / c->mu;
}

static double outer(void *vc, double t)
{
    struct ctx *c = vc;
    c->t = t;
    c->sh = sqrt(fmax(0.0, 1.0 - t * t));
    if (!(t > 0.0))
        return 0.0;
    double denom = 2.0 * t * c->so * c->sh;
    double num = c->mu * (1.0 - 2.0 * t * t);
    double lim;
    if (num >= denom)
        return 0.0;
    lim = num <= -denom ? M_PI : acos(num / denom);
    return 2.0 * adapt(inner, c, 0.0, lim, 1e-11 * (1.0 + 0.0), 0);
}

double sheen_albedo_quad(double mu, double r)
{
    struct lobe l = make_lobe(r);
    struct ctx c = {&l, mu, sqrt(fmax(0.0, 1.0 - mu * mu)), 0.0, 0.0};
    /* pieces fine near t = 0, where the lobe is */
    static const double cut[] = {0.0, 0.01, 0.02, 0.05, 0.1, 0.2, 0.35, 0.5, 0.75, 1.0};
    double s = 0.0;
    for (int i = 0; i + 1 < (int)(sizeof(cut) / sizeof(cut[0])); i++)
        s += adapt(outer, &c, cut[i], cut[i + 1], 1e-11, 0);
    return s;
}

#ifndef SHEEN_GEN_NO_MAIN
int main(int argc, char **argv)
{
    if (argc > 1 && argv[1][0] == 'q') {   /* `q mu r`: one value (checks) */
        printf("%.10f\n", sheen_albedo_quad(atof(argv[2]), atof(argv[3])));
        return 0;
    }
    printf("/* Generated by scripts/sheen_albedo_gen.c (make sheen-table): do not edit.\n"
           " * E(mu, r), the Estevez-Kulla sheen lobe's directional albedo with a white\n"
           " * colour, on the grid of sheen_albedo.h (rows: r; columns: mu). */\n"
           "#include \"sheen_albedo.h\"\n\n"
           "const double DR_SHEEN_ALBEDO[DR_SHEEN_NR][DR_SHEEN_NMU] = {\n");
    for (int j = 0; j < DR_SHEEN_NR; j++) {
        printf("    {");
        for (int i = 0; i < DR_SHEEN_NMU; i++)
            printf("%.9f%s", sheen_albedo_quad(fmax(dr_sheen_grid_mu(i), DR_SHEEN_MU_LO), dr_sheen_grid_r(j)),
                   i + 1 < DR_SHEEN_NMU ? (i % 6 == 5 ? ",\n     " : ", ") : "");
        printf("}%s\n", j + 1 < DR_SHEEN_NR ? "," : "");
    }
    printf("};\n");
    return 0;
}
#endif
