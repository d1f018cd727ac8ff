/* Fused CPU kernels of the fast model: trilinear gather/scatter on a dense grid, ray marching
 * through an occupancy grid, and a lazy Adam update of grid rows; and the export's z-buffer
 * (rasterise_faces).
 *
 * Plain C (no torch headers) so it compiles in well under a second; windowshop/field/kernels.py
 * builds it on first use, caches the library and calls it through ctypes. Each function has a
 * pure-PyTorch twin (grid.py, occupancy.py, optim.py, export/raster.py) that the tests hold it
 * to; floating-point contraction is disabled at compile time so both evaluate the same
 * expressions the same way.
 *
 * Layouts: a grid of X*Y*Z vertices with C channels is a row-major (X, Y, Z, C) float array;
 * points are in grid units, vertex (i, j, k) at (i, j, k). Corner c = 4*dx + 2*dy + dz.
 */
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#ifdef _OPENMP
#include <omp.h>
#endif

typedef int64_t i64;

/* Runs the statement with W, the channel count, a compile-time constant for the density grid's
 * one channel, whose loops then vanish: its interpolation takes half the time. (The features'
 * 16 as a constant made their kernels 1.5x slower with this compiler: left general.) */
#define BY_WIDTH(C, ...)                                                           \
    do {                                                                           \
        if ((C) == 1) { const i64 W = 1; __VA_ARGS__; }                            \
        else { const i64 W = (C); __VA_ARGS__; }                                   \
    } while (0)

/* The cell of a point and its fractional position, clamped into the grid. */
static inline void cell_of(float g, i64 n, i64 *i, float *f) {
    float top = (float)(n - 1);
    g = g < 0.0f ? 0.0f : (g > top ? top : g);
    i64 k = (i64)floorf(g);
    if (k > n - 2) k = n - 2;
    *i = k;
    *f = g - (float)k;
}

/* Row offsets and weights of the 8 corners around point p (3 floats, grid units). */
static inline i64 corners(const float *p, i64 X, i64 Y, i64 Z, i64 off[8], float w[8]) {
    i64 ix, iy, iz;
    float fx, fy, fz;
    cell_of(p[0], X, &ix, &fx);
    cell_of(p[1], Y, &iy, &fy);
    cell_of(p[2], Z, &iz, &fz);
    float wx[2] = {1.0f - fx, fx}, wy[2] = {1.0f - fy, fy}, wz[2] = {1.0f - fz, fz};
    for (int c = 0; c < 8; c++) {
        int dx = c >> 2, dy = (c >> 1) & 1, dz = c & 1;
        off[c] = (dx * Y + dy) * Z + dz;
        w[c] = (wx[dx] * wy[dy]) * wz[dz];
    }
    return (ix * Y + iy) * Z + iz;
}

/* o (C,) = trilinear interpolation of values (X*Y*Z, C) at point p (grid units). */
static inline void interp(const float *values, i64 X, i64 Y, i64 Z, i64 C, const float *p,
                          float *o) {
    i64 off[8];
    float w[8];
    i64 base = corners(p, X, Y, Z, off, w);
    for (i64 ch = 0; ch < C; ch++) o[ch] = 0.0f;
    for (int c = 0; c < 8; c++) {
        const float *v = values + (base + off[c]) * C;
        for (i64 ch = 0; ch < C; ch++) o[ch] += w[c] * v[ch];
    }
}

/* accum (X*Y*Z, C) += the gradient of interp at p given its output's gradient g (C,). */
static inline void scatter(const float *p, i64 X, i64 Y, i64 Z, i64 C, const float *g,
                           float *accum, uint8_t *touched) {
    i64 off[8];
    float w[8];
    i64 base = corners(p, X, Y, Z, off, w);
    for (int c = 0; c < 8; c++) {
        i64 row = base + off[c];
        float *a = accum + row * C;
        for (i64 ch = 0; ch < C; ch++) a[ch] += w[c] * g[ch];
        touched[row] = 1;
    }
}

/* out (N, C) = trilinear interpolation of values (X*Y*Z, C) at points (N, 3). */
void trilinear_forward(const float *values, i64 X, i64 Y, i64 Z, i64 C, const float *points,
                       i64 N, float *out) {
#pragma omp parallel for schedule(static)
    for (i64 n = 0; n < N; n++)
        BY_WIDTH(C, interp(values, X, Y, Z, W, points + 3 * n, out + n * W));
}

/* The x cell of point p: the first index of the rows its interpolation reads. */
static inline i64 cell_x(const float *p, i64 X) {
    i64 i;
    float f;
    cell_of(p[0], X, &i, &f);
    return i;
}

/* accum (X*Y*Z, C) += the gradient of the interpolation at points (N, 3) given grad_out (N, C);
 * touched[row] = 1 for every row written. Rows are shared between samples, so each thread owns a
 * slab of x and scatters the samples whose rows (x cells ix and ix + 1) lie inside it; the few
 * samples straddling two slabs are scattered serially afterwards. */
void trilinear_backward(const float *points, i64 N, i64 X, i64 Y, i64 Z, i64 C,
                        const float *grad_out, float *accum, uint8_t *touched) {
    i64 slabs = 1;
#ifdef _OPENMP
    slabs = omp_get_max_threads();
#endif
    if (slabs < 2 || X < 4 * slabs) {
        for (i64 n = 0; n < N; n++)
            BY_WIDTH(C, scatter(points + 3 * n, X, Y, Z, W, grad_out + n * W, accum, touched));
        return;
    }
#pragma omp parallel for schedule(static, 1)
    for (i64 s = 0; s < slabs; s++) {
        i64 x0 = s * X / slabs, x1 = (s + 1) * X / slabs;
        for (i64 n = 0; n < N; n++) {
            i64 ix = cell_x(points + 3 * n, X);
            if (ix >= x0 && ix + 1 < x1)
                BY_WIDTH(C, scatter(points + 3 * n, X, Y, Z, W, grad_out + n * W, accum, touched));
        }
    }
    for (i64 n = 0; n < N; n++) {
        i64 ix = cell_x(points + 3 * n, X);
        for (i64 s = 1; s < slabs; s++) {
            if (ix + 1 == s * X / slabs)
                scatter(points + 3 * n, X, Y, Z, C, grad_out + n * C, accum, touched);
        }
    }
}

/* The touched rows of [lo, hi) in increasing order, written to rows unless it is NULL; returns
 * how many. A step touches a few percent of a fine grid's rows, in clumps, so whole 8-byte words
 * of flags (0 or 1 each) are counted at once and skipped when zero. */
static i64 scan_span(const uint8_t *touched, i64 lo, i64 hi, i64 *rows) {
    i64 m = 0, r = lo;
    for (; r < hi && (r & 7); r++)
        if (touched[r]) { if (rows) rows[m] = r; m++; }
    for (; r + 8 <= hi; r += 8) {
        uint64_t word;
        memcpy(&word, touched + r, 8);
        if (!word) continue;
        if (!rows) { m += __builtin_popcountll(word); continue; }
        /* a flag of 1 is bit 0 of its byte, byte k bits 8k.. (little-endian): take the lowest set
         * bit and clear it, once per touched row instead of 8 tests a word */
        for (; word; word &= word - 1)
            rows[m++] = r + (__builtin_ctzll(word) >> 3);
    }
    for (; r < hi; r++)
        if (touched[r]) { if (rows) rows[m] = r; m++; }
    return m;
}

/* The touched rows in increasing order: writes them to rows and returns how many. The flags are
 * cut into spans that threads count, then fill from their offsets (a fine grid has millions). */
i64 touched_rows(const uint8_t *touched, i64 V, i64 *rows) {
    enum { SPANS = 64 };
    i64 start[SPANS + 1] = {0};
#pragma omp parallel for schedule(static)
    for (int s = 0; s < SPANS; s++)
        start[s + 1] = scan_span(touched, V * s / SPANS, V * (s + 1) / SPANS, NULL);
    for (int s = 0; s < SPANS; s++) start[s + 1] += start[s];
#pragma omp parallel for schedule(static)
    for (int s = 0; s < SPANS; s++)
        scan_span(touched, V * s / SPANS, V * (s + 1) / SPANS, rows + start[s]);
    return start[SPANS];
}

/* values (M, C) = accum[rows]; then those accum rows and touched flags are cleared (plain loops:
 * a row is 1-16 floats, too short for memcpy's call to pay). */
void harvest_rows(float *accum, uint8_t *touched, i64 C, const i64 *rows, i64 M, float *values) {
#pragma omp parallel for schedule(static)
    for (i64 i = 0; i < M; i++) {
        float *a = accum + rows[i] * C, *v = values + i * C;
        for (i64 ch = 0; ch < C; ch++) {
            v[ch] = a[ch];
            a[ch] = 0.0f;
        }
        touched[rows[i]] = 0;
    }
}

/* Distance of sample k of a ray: t0 + (k + offset) * step. */
static inline float sample_t(float t0, i64 k, float offset, float step) {
    return t0 + ((float)k + offset) * step;
}

#define BLOCK 4 /* cells per side of a coarse occupancy block */

/* An occupancy grid of dims cells tiling the box from lo (inv_cell cells per unit length), and
 * its coarse twin: block (i, j, k) is set when any of its BLOCK^3 cells is. */
typedef struct {
    const uint8_t *occ, *coarse;
    i64 dims[3], cdims[3];
    const float *lo, *inv_cell;
} Occupancy;

/* Visit sample k (at distance t) of the ray o + t d: *hit says whether its cell is occupied.
 * Returns the next sample worth visiting: k + 1, or, in an empty block, the first sample one step
 * before the block's exit (so rounding can never skip a sample of the next block). */
static inline i64 visit(const Occupancy *g, const float *o, const float *d, float t, float t0,
                        float offset, float step, i64 k, int *hit) {
    i64 idx[3], c[3];
    float p[3];
    for (int a = 0; a < 3; a++) {
        p[a] = o[a] + t * d[a];
        i64 i = (i64)floorf((p[a] - g->lo[a]) * g->inv_cell[a]);
        idx[a] = i < 0 ? 0 : (i >= g->dims[a] ? g->dims[a] - 1 : i);
        c[a] = idx[a] / BLOCK;
    }
    if (g->coarse[(c[0] * g->cdims[1] + c[1]) * g->cdims[2] + c[2]]) {
        *hit = g->occ[(idx[0] * g->dims[1] + idx[1]) * g->dims[2] + idx[2]];
        return k + 1;
    }
    *hit = 0;
    float t_exit = INFINITY;
    for (int a = 0; a < 3; a++) {
        if (d[a] == 0.0f) continue;
        float face = g->lo[a] + (float)((d[a] > 0.0f ? c[a] + 1 : c[a]) * BLOCK) / g->inv_cell[a];
        float ta = t + (face - p[a]) / d[a];
        t_exit = ta < t_exit ? ta : t_exit;
    }
    float next = ceilf((t_exit - step - t0) / step - offset);
    return next > (float)(k + 1) ? (i64)next : k + 1;
}

/* March ray r: its occupied samples in [t_min, t_max), the first `room` of them written to t_out
 * and ray_out; returns how many there are (which may be more than room). */
static inline i64 march_ray(const float *origins, const float *dirs, const float *t_min,
                            const float *t_max, const float *offsets, i64 r, float step,
                            const Occupancy *g, i64 room, float *t_out, i64 *ray_out) {
    const float *o = origins + 3 * r, *d = dirs + 3 * r;
    i64 n = 0;
    for (i64 k = 0;;) {
        float t = sample_t(t_min[r], k, offsets[r], step);
        if (!(t < t_max[r])) break;
        int hit;
        k = visit(g, o, d, t, t_min[r], offsets[r], step, k, &hit);
        if (!hit) continue;
        if (n < room) {
            t_out[n] = t;
            ray_out[n] = r;
        }
        n++;
    }
    return n;
}

/* Samples of each ray in [t_min, t_max) whose cell is occupied, in one pass: the rays are cut into
 * `parts` runs, each marched by one thread into its own `room` slots of t_out and ray_out (from
 * part * room), then the runs are packed together. Returns the number of samples S, or -1 when a
 * run had no room for all of its own (the caller then fills with march_fill from counts). counts
 * (R,) gets every ray's samples either way. */
i64 march_packed(const float *origins, const float *dirs, const float *t_min, const float *t_max,
                 const float *offsets, i64 R, float step, const Occupancy *g, i64 parts, i64 room,
                 float *t_out, i64 *ray_out, i64 *counts, i64 *used) {
    int overflow = 0;
#pragma omp parallel for schedule(dynamic, 1) reduction(| : overflow)
    for (i64 p = 0; p < parts; p++) {
        i64 s = p * room, end = s + room;
        for (i64 r = R * p / parts; r < R * (p + 1) / parts; r++) {
            i64 left = s < end ? end - s : 0;
            counts[r] = march_ray(origins, dirs, t_min, t_max, offsets, r, step, g, left,
                                  t_out + s, ray_out + s);
            s += counts[r];
        }
        used[p] = s - p * room;
        overflow |= s > end;
    }
    if (overflow) return -1;
    i64 total = 0;
    for (i64 p = 0; p < parts; p++) {
        memmove(t_out + total, t_out + p * room, (size_t)used[p] * sizeof(float));
        memmove(ray_out + total, ray_out + p * room, (size_t)used[p] * sizeof(i64));
        total += used[p];
    }
    return total;
}

/* march_packed's samples written out from known counts: distances t (S,) and ray indices (S,),
 * ray r's from starts[r]. */
void march_fill(const float *origins, const float *dirs, const float *t_min, const float *t_max,
                const float *offsets, i64 R, float step, const Occupancy *g, const i64 *starts,
                float *t_out, i64 *ray_out) {
#pragma omp parallel for schedule(dynamic, 64)
    for (i64 r = 0; r < R; r++)
        march_ray(origins, dirs, t_min, t_max, offsets, r, step, g, INT64_MAX, t_out + starts[r],
                  ray_out + starts[r]);
}

/* Compositing weights of packed ray samples (NeRF eq. 3) and their per-ray sums: ray r's samples
 * start at starts[r], counts[r] of them in order of distance t, each an interval of length dt with
 * density sigma; w = T (1 - exp(-sigma dt)), T = exp(-the earlier samples' optical depth), the
 * optical depth summed in double as packed_weights does. opacity (R,) = sum w, depth (R,) = sum w t. */
void ray_weights_forward(const float *sigma, const float *t, const i64 *starts, const i64 *counts,
                         i64 R, float dt, float *w, float *opacity, float *depth) {
#pragma omp parallel for schedule(dynamic, 64)
    for (i64 r = 0; r < R; r++) {
        double before = 0.0;
        float o = 0.0f, d = 0.0f;
        for (i64 n = starts[r]; n < starts[r] + counts[r]; n++) {
            float optical = sigma[n] * dt;
            w[n] = (float)exp(-before) * (1.0f - expf(-optical));
            before += (double)optical;
            o += w[n];
            d += w[n] * t[n];
        }
        opacity[r] = o;
        depth[r] = d;
    }
}

/* The density's gradient grad_sigma (N,) of ray_weights_forward, given the gradients of w (N,),
 * opacity and depth (R,): with G_k = grad_w[k] + grad_opacity[r] + grad_depth[r] t[k],
 * dL/dsigma_i = dt (G_i T_{i+1} - sum over the ray's later samples k of G_k w_k). */
void ray_weights_backward(const float *sigma, const float *t, const float *w, const i64 *starts,
                          const i64 *counts, i64 R, float dt, const float *grad_w,
                          const float *grad_opacity, const float *grad_depth, float *grad_sigma) {
#define G(n) ((double)(grad_w[n] + grad_opacity[r] + grad_depth[r] * t[n]))
#pragma omp parallel for schedule(dynamic, 64)
    for (i64 r = 0; r < R; r++) {
        i64 lo = starts[r], hi = starts[r] + counts[r];
        double later = 0.0, before = 0.0;
        for (i64 n = lo; n < hi; n++) later += G(n) * w[n];
        for (i64 n = lo; n < hi; n++) {
            double g = G(n);
            before += (double)(sigma[n] * dt);
            later -= g * w[n];
            grad_sigma[n] = (float)(dt * (g * exp(-before) - later));
        }
    }
#undef G
}

/* Lazy Adam on rows (M,) of param, exp_avg, exp_avg_sq (V, C) with their gradients grad (M, C).
 * lr_c is lr / (1 - beta1^t); sqrt_c2 is sqrt(1 - beta2^t). */
void adam_rows(float *restrict param, float *restrict exp_avg, float *restrict exp_avg_sq, i64 C,
               const i64 *rows, i64 M, const float *restrict grad, float lr_c, float beta1,
               float beta2, float eps, float sqrt_c2) {
#pragma omp parallel for schedule(static)
    for (i64 i = 0; i < M; i++) {
        i64 at = rows[i] * C;
        for (i64 ch = 0; ch < C; ch++) {
            float g = grad[i * C + ch];
            float m = beta1 * exp_avg[at + ch] + (1.0f - beta1) * g;
            float v = beta2 * exp_avg_sq[at + ch] + (1.0f - beta2) * g * g;
            exp_avg[at + ch] = m;
            exp_avg_sq[at + ch] = v;
            param[at + ch] -= lr_c * m / (sqrtf(v) / sqrt_c2 + eps);
        }
    }
}

/* Render-time marching with early termination and compositing, in one pass: each occupied
 * sample's density is interpolated from the one-channel grid `density` (X, Y, Z) as
 * softplus(raw + shift) * scale (grid units: g = (x - lo) * inv_voxel), transmittance T is
 * accumulated, and the ray stops once T < threshold, after which no sample can weigh more. Samples
 * with weight w = T (1 - exp(-sigma step)) >= threshold add w times their interpolated features
 * (`features` (X, Y, Z, C), the same lattice as `density`, so both share the corner weights) to
 * the ray's composited features: the samples themselves are never stored. */
typedef struct {
    const float *origins, *dirs, *t_min, *t_max;
    i64 R;
    float step;
    const Occupancy *grid;
    const float *density, *features;
    i64 X, Y, Z, C;
    const float *inv_voxel;
    float shift, scale, threshold;
} RenderMarch;

static inline float softplus(float x) { return x > 20.0f ? x : log1pf(expf(x)); }

/* March ray r: composited features out (C,), opacity, depth; returns the samples composited. */
static i64 render_ray(const RenderMarch *m, i64 r, float *out, float *opacity, float *depth) {
    const float *o = m->origins + 3 * r, *d = m->dirs + 3 * r;
    const i64 C = m->C;
    float trans = 1.0f, acc_depth = 0.0f;
    i64 n = 0;
    for (i64 ch = 0; ch < C; ch++) out[ch] = 0.0f;
    for (i64 k = 0;;) {
        float t = sample_t(m->t_min[r], k, 0.5f, m->step);
        if (!(t < m->t_max[r]) || trans < m->threshold) break;
        int hit;
        k = visit(m->grid, o, d, t, m->t_min[r], 0.5f, m->step, k, &hit);
        if (!hit) continue;
        float g[3], w[8];
        i64 off[8];
        for (int a = 0; a < 3; a++) g[a] = (o[a] + t * d[a] - m->grid->lo[a]) * m->inv_voxel[a];
        i64 base = corners(g, m->X, m->Y, m->Z, off, w);
        float raw = 0.0f;
        for (int c = 0; c < 8; c++) raw += w[c] * m->density[base + off[c]];
        float alpha = 1.0f - expf(-softplus(raw + m->shift) * m->scale * m->step);
        float weight = trans * alpha;
        acc_depth += weight * t;
        if (weight >= m->threshold) {
            for (int c = 0; c < 8; c++) {
                const float *v = m->features + (base + off[c]) * C;
                float wc = weight * w[c];
                for (i64 ch = 0; ch < C; ch++) out[ch] += wc * v[ch];
            }
            n++;
        }
        trans *= 1.0f - alpha;
    }
    *opacity = 1.0f - trans;
    *depth = acc_depth;
    return n;
}

void render_composite(const RenderMarch *m, float *out, float *opacity, float *depth, i64 *counts) {
#pragma omp parallel for schedule(dynamic, 64)
    for (i64 r = 0; r < m->R; r++)
        counts[r] = render_ray(m, r, out + r * m->C, opacity + r, depth + r);
}

/* Grid units of sample i of packed ray samples: origins[ray[i]] + t[i] * dirs[ray[i]]. */
static inline void sample_point(const float *origins, const float *dirs, const float *t,
                                const i64 *ray, i64 i, const float *lo, const float *inv_voxel,
                                float g[3]) {
    const float *o = origins + 3 * ray[i], *d = dirs + 3 * ray[i];
    for (int a = 0; a < 3; a++) g[a] = (o[a] + t[i] * d[a] - lo[a]) * inv_voxel[a];
}

/* Interpolate values (X*Y*Z, C) at each of N ray samples: out (N, C). */
void trilinear_rays_forward(const float *values, i64 X, i64 Y, i64 Z, i64 C,
                            const float *origins, const float *dirs, const float *t,
                            const i64 *ray, i64 N, const float *lo, const float *inv_voxel,
                            float *out) {
#pragma omp parallel for schedule(static)
    for (i64 n = 0; n < N; n++) {
        float g[3];
        sample_point(origins, dirs, t, ray, n, lo, inv_voxel, g);
        BY_WIDTH(C, interp(values, X, Y, Z, W, g, out + n * W));
    }
}

/* Grid units (N, 3) of all N ray samples, into points. */
static void ray_points(const float *origins, const float *dirs, const float *t, const i64 *ray,
                       i64 N, const float *lo, const float *inv_voxel, float *points) {
#pragma omp parallel for schedule(static)
    for (i64 n = 0; n < N; n++) sample_point(origins, dirs, t, ray, n, lo, inv_voxel, points + 3 * n);
}

/* The gradient of trilinear_rays_forward: accum (X*Y*Z, C) += ..., touched rows marked.
 * points (N, 3) is scratch space. */
void trilinear_rays_backward(i64 X, i64 Y, i64 Z, i64 C, const float *origins, const float *dirs,
                             const float *t, const i64 *ray, i64 N, const float *lo,
                             const float *inv_voxel, const float *grad_out, float *accum,
                             uint8_t *touched, float *points) {
    ray_points(origins, dirs, t, ray, N, lo, inv_voxel, points);
    trilinear_backward(points, N, X, Y, Z, C, grad_out, accum, touched);
}

/* Per-ray weighted sums out (R, C) = sum_i w[i] f_i of the interpolated values f_i (saved to
 * features (N, C)) of ray samples sorted by ray, ray r's from starts[r] for counts[r]. */
void composite_rays_forward(const float *values, i64 X, i64 Y, i64 Z, i64 C,
                            const float *origins, const float *dirs, const float *t,
                            const i64 *ray, const float *w, const i64 *starts, const i64 *counts,
                            i64 R, const float *lo, const float *inv_voxel, float *features,
                            float *out) {
#pragma omp parallel for schedule(dynamic, 64)
    for (i64 r = 0; r < R; r++) {
        float *o = out + r * C;
        for (i64 ch = 0; ch < C; ch++) o[ch] = 0.0f;
        for (i64 n = starts[r]; n < starts[r] + counts[r]; n++) {
            float g[3], *f = features + n * C;
            sample_point(origins, dirs, t, ray, n, lo, inv_voxel, g);
            interp(values, X, Y, Z, C, g, f);
            for (i64 ch = 0; ch < C; ch++) o[ch] += w[n] * f[ch];
        }
    }
}

/* The gradients of composite_rays_forward given grad_out (R, C): grad_w (N,), and
 * accum (X*Y*Z, C) += the values' gradient, touched rows marked. points (N, 3) and
 * grad_samples (N, C) are scratch space. */
void composite_rays_backward(i64 X, i64 Y, i64 Z, i64 C, const float *origins, const float *dirs,
                             const float *t, const i64 *ray, const float *w, i64 N,
                             const float *lo, const float *inv_voxel, const float *features,
                             const float *grad_out, float *grad_w, float *accum,
                             uint8_t *touched, float *points, float *grad_samples) {
#pragma omp parallel for schedule(static)
    for (i64 n = 0; n < N; n++) {
        const float *g_out = grad_out + ray[n] * C, *f = features + n * C;
        float dot = 0.0f, *g = grad_samples + n * C;
        for (i64 ch = 0; ch < C; ch++) {
            dot += f[ch] * g_out[ch];
            g[ch] = w[n] * g_out[ch];
        }
        grad_w[n] = dot;
    }
    ray_points(origins, dirs, t, ray, N, lo, inv_voxel, points);
    trilinear_backward(points, N, X, Y, Z, C, grad_samples, accum, touched);
}

/* The first and last rows (out[0], out[1]) of an image H rows high whose pixel centres the
 * triangle of vertex indices `v` (3) may cover; none (out[0] > out[1]) where a corner
 * is nearer than `near`. */
static inline void face_rows(const double *xy, const double *depth, const i64 *v, i64 H,
                             double near, i64 out[2]) {
    out[0] = 0;
    out[1] = -1;
    if (!(depth[v[0]] > near && depth[v[1]] > near && depth[v[2]] > near)) return;
    double ay = xy[2 * v[0] + 1], by = xy[2 * v[1] + 1], cy = xy[2 * v[2] + 1];
    double ly = fmin(ay, fmin(by, cy)), hy = fmax(ay, fmax(by, cy));
    out[0] = (i64)fmax(0.0, ceil(ly - 0.5));
    out[1] = (i64)fmin((double)(H - 1), floor(hy - 0.5));
}

/* The nearest of the triangles `faces` (F, 3) at each pixel centre of a W x H image: `face`
 * (H*W) gets its index (-1 where none), `zbuf` (H*W) its depth. `xy` (V, 2) are the vertices'
 * pixel coordinates (centres at +0.5), `depth` (V,) their depths along the view; triangles with
 * a corner nearer than `near` are skipped. The same tests as export/raster.py's twin: a pixel is
 * inside when its three edge weights share a sign, its depth is perspective-correct. Each thread
 * owns a band of rows and draws every face's part in it, the faces in order, so exact ties keep
 * the lower index and the result is the same on any number of threads. */
void rasterise_faces(const double *xy, const double *depth, const i64 *faces, i64 F, i64 W, i64 H,
                     double near, double *zbuf, i64 *face) {
    i64 bands = 1;
#ifdef _OPENMP
    bands = omp_get_max_threads();
#endif
    if (bands > H) bands = H > 0 ? H : 1;
    /* each face's rows of pixel centres, found once: a band then skips the faces outside it
     * reading two numbers, not nine (without the memory, each band finds them itself) */
    i64 *rows = malloc(2 * (F > 0 ? F : 1) * sizeof(i64));
    if (rows) {
#pragma omp parallel for schedule(static) if (bands > 1)
        for (i64 f = 0; f < F; ++f) face_rows(xy, depth, faces + 3 * f, H, near, rows + 2 * f);
    }
#pragma omp parallel for schedule(static, 1) if (bands > 1)
    for (i64 b = 0; b < bands; ++b) {
        i64 r0 = b * H / bands, r1 = (b + 1) * H / bands;  /* rows [r0, r1) */
        for (i64 i = r0 * W; i < r1 * W; ++i) {
            zbuf[i] = INFINITY;
            face[i] = -1;
        }
        for (i64 f = 0; f < F; ++f) {
            i64 own[2];
            const i64 *span = rows ? rows + 2 * f : own;
            if (!rows) face_rows(xy, depth, faces + 3 * f, H, near, own);
            i64 y0 = span[0] > r0 ? span[0] : r0, y1 = span[1] < r1 - 1 ? span[1] : r1 - 1;
            if (y0 > y1) continue;
            const i64 *v = faces + 3 * f;
            double ax = xy[2 * v[0]], ay = xy[2 * v[0] + 1], da = depth[v[0]];
            double bx = xy[2 * v[1]], by = xy[2 * v[1] + 1], db = depth[v[1]];
            double cx = xy[2 * v[2]], cy = xy[2 * v[2] + 1], dc = depth[v[2]];
            double area = (bx - ax) * (cy - ay) - (by - ay) * (cx - ax);
            if (fabs(area) < 1e-12) area = 1e-12;
            double lx = fmin(ax, fmin(bx, cx)), hx = fmax(ax, fmax(bx, cx));
            i64 x0 = (i64)fmax(0.0, ceil(lx - 0.5)), x1 = (i64)fmin((double)(W - 1), floor(hx - 0.5));
            for (i64 y = y0; y <= y1; ++y) {
                double py = (double)y + 0.5;
                for (i64 x = x0; x <= x1; ++x) {
                    double px = (double)x + 0.5;
                    double e0 = (cx - bx) * (py - by) - (cy - by) * (px - bx);
                    double e1 = (ax - cx) * (py - cy) - (ay - cy) * (px - cx);
                    double e2 = (bx - ax) * (py - ay) - (by - ay) * (px - ax);
                    /* the weights e / area share their signs with e (area is never 0), so the
                     * inside test needs no division (most pixels of a face's box are outside);
                     * bitwise, it is one branch a pixel, not up to six mispredicted ones */
                    int inside = ((e0 >= 0) & (e1 >= 0) & (e2 >= 0)) | ((e0 <= 0) & (e1 <= 0) & (e2 <= 0));
                    if (!inside) continue;
                    double w0 = e0 / area, w1 = e1 / area, w2 = e2 / area;
                    double inv = w0 / da + w1 / db + w2 / dc;
                    double z = 1.0 / (inv > 1e-12 ? inv : 1e-12);
                    i64 i = y * W + x;
                    if (z < zbuf[i]) {
                        zbuf[i] = z;
                        face[i] = f;
                    }
                }
            }
        }
    }
    free(rows);
}
