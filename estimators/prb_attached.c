/* Path replay backpropagation with attached sampling (the seed's version,
 * after Vicini et al. 2021): constant memory in path length.
 *
 * Under attached sampling each vertex k hands a moving state to the next:
 * s_{k+1} = (the point p_k, the direction d_{k+1}, the density pdf_k that
 * sampled it). The tape carries the adjoint of that state backward
 * (d_path_vertex_attached); PRB walks forward and must know it at each vertex
 * without a tape. In tangent coordinates (p: 2 in the plane of p_k's
 * triangle, d: 2 normal to d_{k+1}, pdf: 1; a constant sky's density moves
 * with d and pdf) the reverse recurrence is
 *     c_k = a_k + M_k^T c_{k+1},
 * with M_k = d s_{k+1} / d s_k (the differentiated sampling map, hit point,
 * frame, ...) and a_k vertex k's own terms. So:
 *  - at the first vertex j whose sampling moves with a parameter, c_{j+1} is
 *    computed by forward mode over the rest of the path (four tangent
 *    directions of p_j and d_{j+1}, their throughput derivatives carried
 *    along: the seed's "dL/domega_0"), and
 *  - at each later vertex c_{k+1} comes from c_k through the inverse of M_k's
 *    position-direction block:  c_{k+1} = M_k^-T (c_k - a_k).  The pdf part
 *    of c_{k+1} does not reach s_{k+2}; it is the next vertex's emission MIS
 *    term, read one vertex ahead.
 * M_k is singular wherever a direction forgets where it came from (a diffuse
 * bounce on a flat triangle: d_{k+1} does not depend on d_k) and
 * near-singular near it, where inverting it loses the adjoint (the seed
 * regularises the inverse and accepts the bias; a regularised inverse of an
 * exactly singular block still drops the lost components). So where
 * sigma_min / sigma_max of the block is below eps (--regularize), the
 * state adjoint is recomputed exactly by forward mode over the rest of the
 * path instead: unbiased, at the price of another walk of the remainder
 * (quadratic in the path length on all-diffuse paths, memory still constant).
 * With eps = 0 the block is always inverted (biased where it is singular).
 * On well-conditioned paths prb and tape agree to rounding.
 *
 * The Jacobian rows and the local terms are obtained from the same reverse-mode
 * vertex adjoint the tape uses (d_path_vertex_attached), with a sink that
 * discards parameter adjoints; so nothing is differentiated twice by hand.
 * Cost per vertex after j: about 9 vertex adjoints in the forward-mode pass
 * and 6 in the replay (the tape: 1), and three walks of the path: the
 * primal (which, with the cross primal, is the caller's: prb.c walks a
 * group of samples in its arrays for their adjoints and hands the sums
 * over), the forward-mode pass and the replay. */
#include "prb_attached.h"

#include "mat4.h"

#include <string.h>

#define NS 5   /* tangent coordinates of a state: p (2), d (2), pdf (1) */
#define ND 4   /* the part that reaches the next state: p, d */

/* Orthonormal bases; position coordinates count in units of the scene's
 * radius (a motion dp has coordinates p . dp / radius, its adjoint
 * radius * p . d_p), so position and direction coordinates are
 * commensurable in the condition test. */
struct state_basis {
    dr_vec3 p[2], d[2];
    dr_vec3 ng;       /* the geometric normal of p_k (a constant sky's density reads d . ng) */
    double share;     /* dr_bsdf_sky_share at p_k */
    double radius;
};

/* What the vertex adjoint gives of one vertex of the path being replayed,
 * kept so that no later walk of the same vertex calls it again: the
 * forward-mode pass computes a vertex's Jacobian rows, the replay needs
 * the same rows of the same vertex in the same bases (bit for bit: the
 * same path, decisions and calls), and a forward-mode pass restarted at a
 * singular vertex walks the rest once more. Indexed by depth (the first
 * CACHED_VERTICES vertices: memory stays constant in path length; deeper
 * vertices are computed every time). Valid for one replay (one adjoint). */
#define CACHED_VERTICES 32
struct vertex_jacobian {
    bool walked;                /* a forward-mode pass filled it (vertex_forward) */
    bool rows;                  /* w and DT hold (the path goes on from it) */
    bool more;                  /* the path goes on from it */
    double w[NS][NS];           /* jacobian_rows: M_k^T e_i */
    double DT[3][NS];           /* the continuation's factor's derivative per channel */
    double ge[NS];              /* the vertex's own terms in tangent coordinates */
    dr_vec3 bt, term, t;        /* true throughput it was reached with, dr_path_vertex_term, f |cos| / pdf / q */
    struct state_basis Tn;      /* the basis of the state it hands on */
};
struct jacobian_cache {
    struct vertex_jacobian v[CACHED_VERTICES];
};

/* The cache's entry for the vertex at depth (NULL: none, or too deep). */
static struct vertex_jacobian *cached_at(const struct prb_attached_ctx *c, int depth)
{
    return c->cache && depth >= 1 && depth <= CACHED_VERTICES ? &c->cache->v[depth - 1] : NULL;
}

static struct vertex_jacobian *cached(const struct prb_attached_ctx *c, const struct dr_path_vertex *v)
{
    return cached_at(c, v->depth);
}

/* Basis of the state vertex v hands on along next_d: the plane of its
 * triangle and the plane normal to next_d. */
static struct state_basis basis_after(const struct dr_path_vertex *v, dr_vec3 next_d, double radius)
{
    dr_frame fp = dr_frame_from_normal(v->ng), fd = dr_frame_from_normal(next_d);
    return (struct state_basis){{fp.s, fp.t}, {fd.s, fd.t}, v->ng, dr_bsdf_sky_share(&v->bsdf, v->wo), radius};
}

static struct dr_d_path_state to_ambient(const struct state_basis *T, const double c[NS])
{
    struct dr_d_path_state r;
    memset(&r, 0, sizeof r);
    if (!T)
        return r;
    r.o = dr_scale(dr_add(dr_scale(T->p[0], c[0]), dr_scale(T->p[1], c[1])), 1.0 / T->radius);
    r.d = dr_add(dr_scale(T->d[0], c[2]), dr_scale(T->d[1], c[3]));
    r.prev_pdf = c[4];
    return r;
}

/* The origin and the previous point are the same point p_{k-1}; a constant
 * sky's density prev_sky = (1 - c) (d . ng) / pi + c pdf (path_attached.c)
 * moves with the d and pdf coordinates, so its adjoint is theirs
 * (to_ambient gives it none). */
static void to_tangent(const struct state_basis *T, const struct dr_d_path_state *r, double c[NS])
{
    dr_vec3 po = dr_add(r->o, r->prev_p);
    const double share = T ? T->share : 0.0;
    dr_vec3 dd = T ? dr_add(r->d, dr_scale(T->ng, (1.0 - share) * DR_INV_PI * r->prev_sky)) : dr_v3s(0.0);
    c[0] = T ? T->radius * dr_dot(T->p[0], po) : 0.0;
    c[1] = T ? T->radius * dr_dot(T->p[1], po) : 0.0;
    c[2] = T ? dr_dot(T->d[0], dd) : 0.0;
    c[3] = T ? dr_dot(T->d[1], dd) : 0.0;
    c[4] = r->prev_pdf + share * r->prev_sky;
}

/* c_out = T_k^T V_k(d_e, d_t, T_{k+1} c_next): vertex v's adjoint in tangent
 * coordinates (Tk may be NULL when s_k does not move; Tn NULL when nothing follows). */
static void vertex_call(const struct prb_attached_ctx *c, const struct dr_path_vertex *v, const struct state_basis *Tk,
                        const struct state_basis *Tn, dr_vec3 d_e, dr_vec3 d_t, const double c_next[NS],
                        double c_out[NS], struct dr_grad_sink *sink)
{
    struct dr_d_path_state dn = to_ambient(Tn, c_next), dt;
    d_path_vertex_attached(c->b->p->scene, &c->b->popts, v, d_e, d_t, &dn, &dt, sink);
    if (c_out)
        to_tangent(Tk, &dt, c_out);
}

/* Rows of M_k (how s_{k+1}'s coordinate i depends on s_k's): w[i] = M_k^T e_i. */
static void jacobian_rows(const struct prb_attached_ctx *c, const struct dr_path_vertex *v,
                          const struct state_basis *Tk, const struct state_basis *Tn, int rows, double w[NS][NS])
{
    for (int i = 0; i < rows; i++) {
        double e[NS] = {0.0, 0.0, 0.0, 0.0, 0.0};
        e[i] = 1.0;
        vertex_call(c, v, Tk, Tn, dr_v3s(0.0), dr_v3s(0.0), e, w[i], NULL);
    }
}

/* ------------------------------------------------- forward mode (dL/ds_{j+1}) */

struct tangents {
    double U[NS][ND];   /* motion of s_k per unit motion of s_{j+1}'s p, d coordinates */
    double dB[3][ND];   /* motion of the true throughput, per channel */
};

/* Vertex v's part of the forward-mode pass into k, once per replay (k
 * holds it already when walked): its own terms in tangent coordinates (Tk,
 * reached with true throughput bt) and, where the path goes on along Tn,
 * the Jacobian rows and the continuation factor's derivative; and the walk's
 * values the sums read, so that a later pass over the same vertices needs
 * neither the vertex adjoint nor the walk. */
static void vertex_forward(const struct prb_attached_ctx *c, const struct dr_path_vertex *v,
                           const struct state_basis *Tk, const struct state_basis *Tn, dr_vec3 bt, dr_vec3 adj,
                           bool more, struct vertex_jacobian *k)
{
    if (k->walked)
        return;
    k->more = more;
    k->bt = bt;
    k->term = dr_path_vertex_term(v);
    k->t = dr_scale(v->f, v->cos_pdf_q);
    vertex_call(c, v, Tk, NULL, dr_mul(adj, bt), dr_v3s(0.0), NULL, k->ge, NULL);
    if (more) {
        k->Tn = *Tn;
        jacobian_rows(c, v, Tk, Tn, NS, k->w);
        for (int ch = 0; ch < 3; ch++) {
            dr_vec3 unit = dr_v3_channel(dr_v3s(1.0), ch);
            vertex_call(c, v, Tk, NULL, dr_v3s(0.0), unit, NULL, k->DT[ch], NULL);
        }
    }
    k->rows = more;
    k->walked = true;
}

/* The forward-mode sums over vertex k: its terms' derivative along each
 * tangent into out; then, where the path goes on, the tangents carried
 * over it: U <- M U, dB <- t dB + bt (dt/ds) U. */
static void tangents_over(const struct vertex_jacobian *k, dr_vec3 adj, struct tangents *g, double out[ND])
{
    dr_vec3 e = dr_mul(adj, k->term);
    for (int col = 0; col < ND; col++) {
        double s = e.x * g->dB[0][col] + e.y * g->dB[1][col] + e.z * g->dB[2][col];
        for (int r = 0; r < NS; r++)
            s += k->ge[r] * g->U[r][col];
        out[col] += s;
    }
    if (!k->more)
        return;
    double U[NS][ND];
    for (int col = 0; col < ND; col++) {
        for (int ch = 0; ch < 3; ch++) {
            double s = 0.0;
            for (int r = 0; r < NS; r++)
                s += k->DT[ch][r] * g->U[r][col];
            g->dB[ch][col] = dr_v3_get(k->t, ch) * g->dB[ch][col] + dr_v3_get(k->bt, ch) * s;
        }
        for (int i = 0; i < NS; i++) {
            double s = 0.0;
            for (int r = 0; r < NS; r++)
                s += k->w[i][r] * g->U[r][col];
            U[i][col] = s;
        }
    }
    memcpy(g->U, U, sizeof U);
}

/* Are the vertices from depth `from` to the path's end all in the cache
 * (a forward-mode pass walked them: the pass need not walk again)? */
static bool rest_cached(const struct prb_attached_ctx *c, int from)
{
    for (int depth = from;; depth++) {
        const struct vertex_jacobian *k = cached_at(c, depth);
        if (!k || !k->walked)
            return false;
        if (!k->more)
            return true;
    }
}

/* dL_{>j} / d s_{j+1} in s_{j+1}'s p and d coordinates (T1), by forward mode
 * over the rest of the path, walked again from state st with sampler smp
 * (or, where an earlier pass walked the whole rest, from the cache). */
static void tangent_walk(const struct prb_attached_ctx *c, struct dr_sampler smp, struct dr_path_state st,
                         const struct state_basis *T1, dr_vec3 adj, double out[ND])
{
    const struct dr_est_base *b = c->b;
    struct tangents g;
    memset(&g, 0, sizeof g);
    for (int i = 0; i < ND; i++)
        g.U[i][i] = 1.0;
    memset(out, 0, sizeof(double) * ND);
    const bool known = rest_cached(c, st.depth + 1);
    struct state_basis Tk = *T1;
    for (;;) {
        struct vertex_jacobian here, *k = cached_at(c, st.depth + 1);   /* (the next vertex's) */
        if (!k) {   /* (past the cache: made here each time) */
            here.walked = false;
            k = &here;
        }
        if (known) {
            st.depth++;   /* (only the depth is read: the cache's index) */
        } else {
            dr_vec3 bt = dr_mul(st.ratio, st.beta);
            struct dr_path_vertex v;
            bool more = dr_wave_log_step(b->p->scene, &b->popts, c->log, &st, &smp, &v, c->rays);
            struct state_basis Tn;
            if (more)
                Tn = basis_after(&v, st.d, c->radius);
            vertex_forward(c, &v, &Tk, more ? &Tn : NULL, bt, adj, more, k);
        }
        tangents_over(k, adj, &g, out);
        if (!k->more)
            return;
        Tk = k->Tn;
    }
}

/* --------------------------------------------------------------- replay */

/* A moving vertex whose derivative waits for the next one (the lookahead). */
struct pending {
    struct dr_path_vertex v;
    dr_vec3 d_e, d_t;
    struct state_basis Tk, Tn;
    bool has_Tk;
    double ck[NS];            /* adjoint of the state it received (when has_Tk) */
    double cn[ND];            /* first moving vertex: the forward-mode result */
    bool first;
    struct dr_path_state st;  /* the state it handed on, and the sampler: */
    struct dr_sampler smp;    /* where a forward-mode pass restarts */
};

/* With the next vertex known: the state adjoint it receives (pdf part read
 * from its emission, p and d parts from the forward-mode pass or through the
 * inverse Jacobian), then the pending vertex's parameter adjoints. Returns
 * the next vertex's c_{k+1} in *c_next. */
static void finish(const struct prb_attached_ctx *c, const struct pending *P, const struct dr_path_vertex *next,
                   dr_vec3 next_d_e, dr_vec3 adj, double c_next[NS], struct dr_grad_sink *sink)
{
    /* (the forward-mode pass made the same call for its own terms: its
     * pdf coordinate is this) */
    const struct vertex_jacobian *kn = cached(c, next);
    if (kn && kn->walked) {
        c_next[4] = kn->ge[4];
    } else {
        struct dr_d_path_state dt, zero;
        memset(&zero, 0, sizeof zero);
        d_path_vertex_attached(c->b->p->scene, &c->b->popts, next, next_d_e, dr_v3s(0.0), &zero, &dt, NULL);
        double ct[NS];
        to_tangent(&P->Tn, &dt, ct);
        c_next[4] = ct[4];
    }
    if (P->first) {
        memcpy(c_next, P->cn, sizeof P->cn);
    } else {
        double pdf_only[NS] = {0.0, 0.0, 0.0, 0.0, c_next[4]}, a[NS], w_here[NS][NS], A[ND][ND], y[ND], x[ND];
        vertex_call(c, &P->v, &P->Tk, &P->Tn, P->d_e, P->d_t, pdf_only, a, NULL);
        /* (the forward-mode pass that reached this vertex computed its rows) */
        struct vertex_jacobian *k = cached(c, &P->v);
        double(*w)[NS] = k && k->rows ? k->w : w_here;
        if (!k || !k->rows)
            jacobian_rows(c, &P->v, &P->Tk, &P->Tn, ND, w);
        for (int r = 0; r < ND; r++) {
            for (int i = 0; i < ND; i++)
                A[r][i] = w[i][r];
            y[r] = P->ck[r] - a[r];
        }
        if (dr_mat4_condition_at_least(A, c->eps)) {
            dr_mat4_solve(A, y, x);
        } else {
            /* (near-)singular: the direction forgot where it came from;
             * forward mode over the rest of the path instead, exactly */
            tangent_walk(c, P->smp, P->st, &P->Tn, adj, x);
        }
        memcpy(c_next, x, sizeof x);
    }
    vertex_call(c, &P->v, P->has_Tk ? &P->Tk : NULL, &P->Tn, P->d_e, P->d_t, c_next, NULL, sink);
}

/* d L / d f of vertex v's continuation from the radiance still to come, times
 * adj (as the detached replay's d_f, prb.c). */
static dr_vec3 continuation_df(const struct dr_path_vertex *v, dr_vec3 ratio, dr_vec3 L_true, dr_vec3 L_sub,
                               dr_vec3 adj)
{
    dr_vec3 d_f = dr_v3s(0.0);
    if (!v->cont)
        return d_f;
    for (int ch = 0; ch < 3; ch++) {
        double f = dr_v3_get(v->f, ch), r;
        if (v->sub[ch])
            r = dr_v3_get(ratio, ch) * dr_v3_get(L_sub, ch) / dr_v3_get(v->s, ch);
        else
            r = f != 0.0 ? dr_v3_get(L_true, ch) / f : 0.0;
        dr_v3_set(&d_f, ch, r * dr_v3_get(adj, ch));
    }
    return d_f;
}

/* d_t of vertex v: d_f divided by |cos| / pdf / q (the adjoint of
 * t = f |cos| / pdf / q). */
static dr_vec3 continuation_adjoint(const struct dr_path_vertex *v, dr_vec3 d_f)
{
    dr_vec3 d_t = dr_v3s(0.0);
    if (!v->cont)
        return d_t;
    for (int ch = 0; ch < 3; ch++)
        dr_v3_set(&d_t, ch, dr_v3_get(d_f, ch) / v->cos_pdf_q);
    return d_t;
}

/* The primal: the path's radiance (prb.c's walk sums the same way). */
static void primal(const struct prb_attached_ctx *c, struct dr_sampler smp, dr_vec3 o, dr_vec3 d,
                   struct prb_attached_sums *w)
{
    const struct dr_est_base *b = c->b;
    struct dr_path_state st;
    struct dr_path_vertex v;
    dr_path_start(&st, o, d);
    *w = (struct prb_attached_sums){dr_v3s(0.0), dr_v3s(0.0)};
    for (;;) {
        dr_vec3 beta = st.beta, ratio = st.ratio;
        bool more = dr_wave_log_step(b->p->scene, &b->popts, c->log, &st, &smp, &v, c->rays);
        dr_vec3 e = dr_mul(beta, dr_path_vertex_term(&v));
        w->L_sub = dr_add(w->L_sub, e);
        w->L_true = dr_add(w->L_true, dr_mul(ratio, e));
        if (!more)
            return;
    }
}

/* The replay: vertices before the first whose sampling moves with a
 * parameter as the detached replay; from it on, each vertex's derivative
 * once the next one is known (the replay finds that vertex as it reaches
 * it: the same path as the primal's). With `det` (mis), every vertex's
 * detached adjoints also go there: the detached estimate of the same path,
 * for no extra ray. */
static void replay(const struct prb_attached_ctx *c, struct dr_sampler smp, dr_vec3 o, dr_vec3 d, dr_vec3 adj,
                   struct prb_attached_sums *w, struct dr_grad_sink *sink, struct dr_grad_sink *det)
{
    const struct dr_est_base *b = c->b;
    const struct dr_scene *s = b->p->scene;
    const struct dr_param_set *ps = b->p->params;
    struct dr_path_state st;
    struct pending P;
    bool have = false, moving = false;   /* moving: this vertex or one before moves */
    dr_path_start(&st, o, d);
    for (;;) {
        dr_vec3 beta = st.beta, ratio = st.ratio, bt = dr_mul(ratio, beta);
        struct dr_path_vertex v;
        bool more = dr_wave_log_step(s, &b->popts, c->log, &st, &smp, &v, c->rays);
        dr_vec3 e = dr_mul(beta, dr_path_vertex_term(&v));
        w->L_sub = dr_sub(w->L_sub, e);
        w->L_true = dr_sub(w->L_true, dr_mul(ratio, e));
        dr_vec3 d_e = dr_mul(adj, bt), d_f = continuation_df(&v, ratio, w->L_true, w->L_sub, adj);
        dr_vec3 d_t = continuation_adjoint(&v, d_f);
        const bool cont_diff = v.cont && v.diff_bsdf;   /* (else the continuation's f adds nothing) */
        if (det)
            d_path_vertex(s, ps, &v, d_e, cont_diff ? d_f : dr_v3s(0.0), det);
        const bool first = !moving && dr_path_vertex_sampling_moves(s, ps, &v);
        moving = moving || first;
        if (!moving) {
            d_path_vertex(s, ps, &v, d_e, cont_diff ? dr_scale(d_t, v.cos_pdf_q) : dr_v3s(0.0), sink);
        } else {
            double c_next[NS];
            if (have)
                finish(c, &P, &v, d_e, adj, c_next, sink);
            P.has_Tk = have;
            if (have) {
                P.Tk = P.Tn;
                memcpy(P.ck, c_next, sizeof P.ck);
            }
            P.v = v;
            P.d_e = d_e;
            P.d_t = d_t;
            P.first = first;
            have = true;
            if (!more) {
                vertex_call(c, &P.v, P.has_Tk ? &P.Tk : NULL, NULL, d_e, d_t, NULL, NULL, sink);
                return;
            }
            P.Tn = basis_after(&v, st.d, c->radius);
            P.st = st;
            P.smp = smp;
            if (P.first)
                tangent_walk(c, smp, st, &P.Tn, adj, P.cn);
        }
        if (!more)
            return;
    }
}

/* replay() with an empty jacobian_cache. */
static void replay_cached(const struct prb_attached_ctx *c, struct dr_sampler smp, dr_vec3 o, dr_vec3 d, dr_vec3 adj,
                          struct prb_attached_sums *w, struct dr_grad_sink *sink, struct dr_grad_sink *det)
{
    struct jacobian_cache cache;   /* (17 KB: flags cleared, the numbers written before they are read) */
    for (int i = 0; i < CACHED_VERTICES; i++)
        cache.v[i].walked = cache.v[i].rows = false;
    struct prb_attached_ctx cc = *c;
    cc.cache = &cache;
    replay(&cc, smp, o, d, adj, w, sink, det);
}

bool prb_attached_sample(const struct prb_attached_ctx *c, struct dr_sampler smp, dr_vec3 o, dr_vec3 d, dr_vec3 adj,
                         const struct prb_attached_sums *sums, struct dr_grad_sink *sink, struct dr_grad_sink *det)
{
    struct prb_attached_sums w;
    if (sums)
        w = *sums;
    else
        primal(c, smp, o, d, &w);
    if (!dr_v3_finite(w.L_true) || !dr_v3_finite(w.L_sub))
        return false;
    if (!sink->dir) {
        replay_cached(c, smp, o, d, adj, &w, sink, det);
        return true;
    }
    /* forward mode: the state adjoint mixes the channels, one replay each */
    for (int ch = 0; ch < 3; ch++) {
        struct prb_attached_sums wc = w;
        sink->channel = ch;
        replay_cached(c, smp, o, d, dr_v3_channel(adj, ch), &wc, sink, det);
    }
    return true;
}
