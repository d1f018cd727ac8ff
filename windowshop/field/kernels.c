/* Fused CPU kernels of the fast model: trilinear gather/scatter on a dense grid, ray marching
 * through an occupancy grid, and a lazy Adam update of grid rows.
 *
 * Plain C (no torch headers) so it compiles in well under a second; windowshop/field/kernels.py
 * builds it on first use, caches the library and calls it through ctypes. Each function has a
 * pure-PyTorch twin (grid.py, occupancy.py, optim.py) that the tests hold it to; floating-point
 * contraction is disabled at compile time so both evaluate the same expressions the same way.
 *
 * Layouts: a grid of X*Y*Z vertices with C channels is a row-major (X, Y, Z, C) float array;
 * points are in grid units, vertex (i, j, k) at (i, j, k). Corner c = 4*dx + 2*dy + dz.
 */
#include <math.h>
#include <stdint.h>
#include <string.h>

typedef int64_t i64;

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

/* out (N, C) = trilinear interpolation of values (X*Y*Z, C) at points (N, 3). */
void trilinear_forward(const float *values, i64 X, i64 Y, i64 Z, i64 C, const float *points,
                       i64 N, float *out) {
#pragma omp parallel for schedule(static)
    for (i64 n = 0; n < N; n++) {
        i64 off[8];
        float w[8];
        i64 base = corners(points + 3 * n, X, Y, Z, off, w);
        float *o = out + n * C;
        for (i64 ch = 0; ch < C; ch++) o[ch] = 0.0f;
        for (int c = 0; c < 8; c++) {
            const float *v = values + (base + off[c]) * C;
            for (i64 ch = 0; ch < C; ch++) o[ch] += w[c] * v[ch];
        }
    }
}

/* accum (X*Y*Z, C) += the gradient of the interpolation at points (N, 3) given grad_out (N, C);
 * touched[row] = 1 for every row written. Serial: rows are shared between samples. */
void trilinear_backward(const float *points, i64 N, i64 X, i64 Y, i64 Z, i64 C,
                        const float *grad_out, float *accum, uint8_t *touched) {
    for (i64 n = 0; n < N; n++) {
        i64 off[8];
        float w[8];
        i64 base = corners(points + 3 * n, X, Y, Z, off, w);
        const float *g = grad_out + n * C;
        for (int c = 0; c < 8; c++) {
            i64 row = base + off[c];
            float *a = accum + row * C;
            for (i64 ch = 0; ch < C; ch++) a[ch] += w[c] * g[ch];
            touched[row] = 1;
        }
    }
}

/* The touched rows in increasing order: writes them to rows and returns how many. */
i64 touched_rows(const uint8_t *touched, i64 V, i64 *rows) {
    i64 m = 0;
    for (i64 r = 0; r < V; r++) {
        if (touched[r]) rows[m++] = r;
    }
    return m;
}

/* values (M, C) = accum[rows]; then those accum rows and touched flags are cleared. */
void harvest_rows(float *accum, uint8_t *touched, i64 C, const i64 *rows, i64 M, float *values) {
#pragma omp parallel for schedule(static)
    for (i64 i = 0; i < M; i++) {
        float *a = accum + rows[i] * C;
        memcpy(values + i * C, a, (size_t)C * sizeof(float));
        memset(a, 0, (size_t)C * sizeof(float));
        touched[rows[i]] = 0;
    }
}

/* Distance of sample k of a ray: t0 + (k + offset) * step. */
static inline float sample_t(float t0, i64 k, float offset, float step) {
    return t0 + ((float)k + offset) * step;
}

/* Whether the point at distance t along the ray lies in an occupied cell of occ (OX, OY, OZ). */
static inline int occupied(const float *o, const float *d, float t, const float *lo,
                           const float *inv_cell, const uint8_t *occ, i64 OX, i64 OY, i64 OZ) {
    i64 dims[3] = {OX, OY, OZ}, idx[3];
    for (int a = 0; a < 3; a++) {
        float p = o[a] + t * d[a];
        i64 i = (i64)floorf((p - lo[a]) * inv_cell[a]);
        idx[a] = i < 0 ? 0 : (i >= dims[a] ? dims[a] - 1 : i);
    }
    return occ[(idx[0] * OY + idx[1]) * OZ + idx[2]];
}

/* Samples of each ray in [t_min, t_max) whose cell is occupied: counts (R,) only. */
void march_count(const float *origins, const float *dirs, const float *t_min, const float *t_max,
                 const float *offsets, i64 R, float step, const uint8_t *occ, i64 OX, i64 OY,
                 i64 OZ, const float *lo, const float *inv_cell, i64 *counts) {
#pragma omp parallel for schedule(dynamic, 64)
    for (i64 r = 0; r < R; r++) {
        i64 n = 0;
        const float *o = origins + 3 * r, *d = dirs + 3 * r;
        for (i64 k = 0;; k++) {
            float t = sample_t(t_min[r], k, offsets[r], step);
            if (!(t < t_max[r])) break;
            n += occupied(o, d, t, lo, inv_cell, occ, OX, OY, OZ);
        }
        counts[r] = n;
    }
}

/* The same samples written out: distances t (S,) and ray indices (S,), ray r from starts[r]. */
void march_fill(const float *origins, const float *dirs, const float *t_min, const float *t_max,
                const float *offsets, i64 R, float step, const uint8_t *occ, i64 OX, i64 OY,
                i64 OZ, const float *lo, const float *inv_cell, const i64 *starts, float *t_out,
                i64 *ray_out) {
#pragma omp parallel for schedule(dynamic, 64)
    for (i64 r = 0; r < R; r++) {
        i64 s = starts[r];
        const float *o = origins + 3 * r, *d = dirs + 3 * r;
        for (i64 k = 0;; k++) {
            float t = sample_t(t_min[r], k, offsets[r], step);
            if (!(t < t_max[r])) break;
            if (occupied(o, d, t, lo, inv_cell, occ, OX, OY, OZ)) {
                t_out[s] = t;
                ray_out[s] = r;
                s++;
            }
        }
    }
}

/* Lazy Adam on rows (M,) of param, exp_avg, exp_avg_sq (V, C) with their gradients grad (M, C).
 * lr_c is lr / (1 - beta1^t); sqrt_c2 is sqrt(1 - beta2^t). */
void adam_rows(float *param, float *exp_avg, float *exp_avg_sq, i64 C, const i64 *rows, i64 M,
               const float *grad, float lr_c, float beta1, float beta2, float eps, float sqrt_c2) {
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

/* Render-time marching with early termination, in two passes (count, then fill) that visit the
 * same samples: each occupied sample's density is interpolated from the one-channel grid
 * `density` (X, Y, Z) as softplus(raw + shift) * scale (grid units: g = (x - lo) * inv_voxel),
 * transmittance T is accumulated, and the ray stops once T < threshold, after which no sample can
 * weigh more. Samples with weight w = T (1 - exp(-sigma step)) >= threshold are emitted. */
typedef struct {
    const float *origins, *dirs, *t_min, *t_max;
    i64 R;
    float step;
    const uint8_t *occ;
    i64 OX, OY, OZ;
    const float *lo, *inv_cell;
    const float *density;
    i64 X, Y, Z;
    const float *inv_voxel;
    float shift, scale, threshold;
} RenderMarch;

static inline float softplus(float x) { return x > 20.0f ? x : log1pf(expf(x)); }

/* March ray r; with t_out == NULL only count the emitted samples. Writes opacity and depth. */
static i64 render_ray(const RenderMarch *m, i64 r, float *t_out, float *w_out, i64 *ray_out,
                      float *opacity, float *depth) {
    const float *o = m->origins + 3 * r, *d = m->dirs + 3 * r;
    float trans = 1.0f, acc_depth = 0.0f;
    i64 n = 0;
    for (i64 k = 0;; k++) {
        float t = sample_t(m->t_min[r], k, 0.5f, m->step);
        if (!(t < m->t_max[r]) || trans < m->threshold) break;
        if (!occupied(o, d, t, m->lo, m->inv_cell, m->occ, m->OX, m->OY, m->OZ)) continue;
        float g[3];
        for (int a = 0; a < 3; a++) g[a] = (o[a] + t * d[a] - m->lo[a]) * m->inv_voxel[a];
        i64 off[8];
        float w[8], raw = 0.0f;
        i64 base = corners(g, m->X, m->Y, m->Z, off, w);
        for (int c = 0; c < 8; c++) raw += w[c] * m->density[base + off[c]];
        float alpha = 1.0f - expf(-softplus(raw + m->shift) * m->scale * m->step);
        float weight = trans * alpha;
        acc_depth += weight * t;
        if (weight >= m->threshold) {
            if (t_out) {
                t_out[n] = t;
                w_out[n] = weight;
                ray_out[n] = r;
            }
            n++;
        }
        trans *= 1.0f - alpha;
    }
    *opacity = 1.0f - trans;
    *depth = acc_depth;
    return n;
}

void render_march_count(const RenderMarch *m, i64 *counts) {
#pragma omp parallel for schedule(dynamic, 64)
    for (i64 r = 0; r < m->R; r++) {
        float opacity, depth;
        counts[r] = render_ray(m, r, NULL, NULL, NULL, &opacity, &depth);
    }
}

void render_march_fill(const RenderMarch *m, const i64 *starts, float *t_out, float *w_out,
                       i64 *ray_out, float *opacity, float *depth) {
#pragma omp parallel for schedule(dynamic, 64)
    for (i64 r = 0; r < m->R; r++) {
        i64 s = starts[r];
        render_ray(m, r, t_out + s, w_out + s, ray_out + s, opacity + r, depth + r);
    }
}
