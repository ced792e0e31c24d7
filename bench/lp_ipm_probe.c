/* Mehrotra's predictor-corrector interior point for an LP window's model: the active bounds of its solution as
   HiGHS's starting basis (bench/lp_ipm_probe.py, a probe; the pipeline's use of it is on branch lp-start, not on
   main: see the probe's docstring for why).

   min cost . y  s.t.  lo <= A y <= hi,  clo <= y <= chi   (A: nr x n CSR, each row's columns within bw of each
   other; infinite bounds as +-inf)

   Every finite bound is one inequality c_k = sg_k (A_r y or y_j) + o_k >= 0 (sg = +1 a lower bound, -1 an upper
   one), slack w_k > 0, multiplier z_k > 0, started at w = max(o, 1), z = 1.  Each iteration, with r_p = c - w,
   D = z / w and a centring target t:

       (G^T D G) dy = G^T z - cost + G^T (t / w - z - D r_p),   dw = G dy + r_p,   dz = t / w - z - D dw

   G^T D G = A^T diag(d_r) A + diag(d_col) (d summed over each row's and column's bounds: sg^2 = 1) is banded
   (half-bandwidth bw), stored in the lower band form band[d n + j] = M(j + d, j) and factored in place by
   Cholesky.  First t = 0 (predictor), then t = sigma mu - dw dz (corrector, sigma = (mu_aff / mu)^3); steps
   `share` of the way to the boundary, w and z separately.  Converged when max |r_p| <= tol (1 + max |o|),
   max |cost - G^T z| <= tol (1 + max |cost|) and w . z <= tol (1 + |cost . y|).

   Returns the iterations taken (>= 0), -1 without convergence in maxit iterations, -2 when the normal matrix does
   not factor (or there are no bounds), -3 when y grows past 1e12, -4 when memory runs out. */
#include <math.h>
#include <stddef.h>
#include <stdlib.h>
#include <string.h>

/* added to the normal matrix's diagonal (the models' rows and columns are scaled to O(1); relative to the largest
   diagonal, as D = z / w reaches ~1e15 on active rows, it stalled the dual residual at ~5e-7) */
#define REGULARISATION 1e-14

/* The model's inequalities: each finite bound of a row or column, k = 0 .. m-1: entity ent[k] (r >= 0 the row r,
   -1 - j the column j), sign sg[k] (+1 a lower bound, -1 an upper one) and offset o[k]:
   c_k = sg_k (A_r y or y_j) + o_k >= 0 */
typedef struct {
    int nr, n, m;
    const int *ptr, *ind;
    const double *val;
    int *ent;
    double *sg, *o;
    double *ay; /* (nr) */
    double *u;  /* (nr) */
} Model;

static void gt_apply(const Model *M, const double *x, double *out) { /* out = G^T x */
    memset(M->u, 0, (size_t)M->nr * sizeof(double));
    memset(out, 0, (size_t)M->n * sizeof(double));
    for (int k = 0; k < M->m; k++) {
        int e = M->ent[k];
        if (e >= 0) M->u[e] += M->sg[k] * x[k];
        else out[-1 - e] += M->sg[k] * x[k];
    }
    for (int r = 0; r < M->nr; r++)
        for (int p = M->ptr[r]; p < M->ptr[r + 1]; p++) out[M->ind[p]] += M->val[p] * M->u[r];
}

static int band_cholesky(int n, int bw, double *b) {
    for (int j = 0; j < n; j++) {
        int k0 = j - bw > 0 ? j - bw : 0;
        double s = b[j];
        for (int k = k0; k < j; k++) s -= b[(j - k) * n + k] * b[(j - k) * n + k];
        if (!(s > 0.0)) return -1;
        double ljj = sqrt(s);
        b[j] = ljj;
        int i1 = j + bw < n - 1 ? j + bw : n - 1;
        for (int i = j + 1; i <= i1; i++) {
            int kk = i - bw > 0 ? i - bw : 0;
            double t = b[(i - j) * n + j];
            for (int k = kk; k < j; k++) t -= b[(i - k) * n + k] * b[(j - k) * n + k];
            b[(i - j) * n + j] = t / ljj;
        }
    }
    return 0;
}

static void band_solve(int n, int bw, const double *b, double *x) { /* L L^T x = x, in place */
    for (int i = 0; i < n; i++) {
        int k0 = i - bw > 0 ? i - bw : 0;
        double s = x[i];
        for (int k = k0; k < i; k++) s -= b[(i - k) * n + k] * x[k];
        x[i] = s / b[i];
    }
    for (int i = n - 1; i >= 0; i--) {
        int k1 = i + bw < n - 1 ? i + bw : n - 1;
        double s = x[i];
        for (int k = i + 1; k <= k1; k++) s -= b[(k - i) * n + i] * x[k];
        x[i] = s / b[i];
    }
}

/* The Newton direction for the centring target t_k = tc - adw_k adz_k (the predictor: tc = 0, adw = adz = NULL,
   t = 0): dy (n), dw, dz (m), and the largest steps in (0, 1] that keep w + a dw and z + a dz >= 0 (ap, ad).  The
   loops over the bounds are fused: ~1 ns an element on the 2-core machine, ~10 passes an iteration. */
static void direction(const Model *M, int bw, const double *band, const double *base, double tc, const double *adw,
                      const double *adz, const double *iw, const double *w, const double *z, const double *D,
                      const double *rp, double *dy, double *dw, double *dz, double *ap, double *ad) {
    int m = M->m, n = M->n, nr = M->nr;
    const int *ent = M->ent;
    const double *sg = M->sg;
    double *u = M->u;
    /* dy = base + G^T (t / w - z - D r_p), solved */
    memset(u, 0, (size_t)nr * sizeof(double));
    memcpy(dy, base, (size_t)n * sizeof(double));
    for (int k = 0; k < m; k++) {
        double t = adw != NULL ? tc - adw[k] * adz[k] : 0.0;
        double x = sg[k] * (t * iw[k] - z[k] - D[k] * rp[k]);
        int e = ent[k];
        if (e >= 0) u[e] += x;
        else dy[-1 - e] += x;
    }
    for (int r = 0; r < nr; r++)
        for (int p = M->ptr[r]; p < M->ptr[r + 1]; p++) dy[M->ind[p]] += M->val[p] * u[r];
    band_solve(n, bw, band, dy);
    /* dw = G dy + r_p, dz = t / w - z - D dw, and the steps */
    for (int r = 0; r < nr; r++) {
        double s = 0.0;
        for (int p = M->ptr[r]; p < M->ptr[r + 1]; p++) s += M->val[p] * dy[M->ind[p]];
        M->ay[r] = s;
    }
    double a_p = 1.0, a_d = 1.0;
    for (int k = 0; k < m; k++) {
        int e = ent[k];
        double t = adw != NULL ? tc - adw[k] * adz[k] : 0.0;
        double dwk = sg[k] * (e >= 0 ? M->ay[e] : dy[-1 - e]) + rp[k];
        double dzk = t * iw[k] - z[k] - D[k] * dwk;
        dw[k] = dwk;
        dz[k] = dzk;
        double sp = dwk < 0.0 ? -w[k] / dwk : 1.0, sd = dzk < 0.0 ? -z[k] / dzk : 1.0;
        a_p = sp < a_p ? sp : a_p;
        a_d = sd < a_d ? sd : a_d;
    }
    *ap = a_p;
    *ad = a_d;
}

/* min cost . y s.t. lo <= A y <= hi, clo <= y <= chi (A: nr x n CSR; infinite bounds as +-inf).  On return (any
   status) each row's and column's largest z / w over its bounds (ratio_row, ratio_col; -1 without a finite
   bound) and whether that bound is the upper one (upper_row, upper_col). */
int fs_lp_ipm(int nr, int n, const int *ptr, const int *ind, const double *val, const double *lo, const double *hi,
              const double *clo, const double *chi, const double *cost, int bw, double tol, int maxit, double share,
              double *y, double *ratio_row, int *upper_row, double *ratio_col, int *upper_col) {
    int m = 0;
    for (int r = 0; r < nr; r++) m += isfinite(lo[r]) + isfinite(hi[r]);
    for (int j = 0; j < n; j++) m += isfinite(clo[j]) + isfinite(chi[j]);
    size_t nb = (size_t)(bw + 1) * (size_t)n;
    double *mem = malloc(sizeof(double) * (nb + 4 * (size_t)n + 2 * (size_t)nr + 12 * (size_t)(m + 1)));
    int *ent = malloc(sizeof(int) * (size_t)(m + 1));
    if (mem == NULL || ent == NULL) {
        free(mem);
        free(ent);
        return -4;
    }
    double *band = mem, *gtz = band + nb, *base = gtz + n, *dy = base + n, *dcol = dy + n;
    double *ay = dcol + n, *u = ay + nr, *sg = u + nr, *o = sg + m, *w = o + m, *z = w + m;
    double *rp = z + m, *D = rp + m, *dwa = D + m, *dza = dwa + m, *dw = dza + m, *dz = dw + m, *iw = dz + m;
    int k = 0;
    for (int r = 0; r < nr; r++) {
        if (isfinite(lo[r])) { ent[k] = r; sg[k] = 1.0; o[k] = -lo[r]; k++; }
        if (isfinite(hi[r])) { ent[k] = r; sg[k] = -1.0; o[k] = hi[r]; k++; }
    }
    for (int j = 0; j < n; j++) {
        if (isfinite(clo[j])) { ent[k] = -1 - j; sg[k] = 1.0; o[k] = -clo[j]; k++; }
        if (isfinite(chi[j])) { ent[k] = -1 - j; sg[k] = -1.0; o[k] = chi[j]; k++; }
    }
    Model M = {nr, n, m, ptr, ind, val, ent, sg, o, ay, u};
    double omax = 0.0, cmax = 0.0;
    for (k = 0; k < m; k++) omax = fmax(omax, fabs(o[k]));
    for (int j = 0; j < n; j++) cmax = fmax(cmax, fabs(cost[j]));
    memset(y, 0, (size_t)n * sizeof(double));
    for (k = 0; k < m; k++) {
        w[k] = o[k] > 1.0 ? o[k] : 1.0;
        z[k] = 1.0;
    }
    int result = m > 0 ? -1 : -2;
    for (int it = 0; it < maxit && m > 0; it++) {
        for (int r = 0; r < nr; r++) {
            double s = 0.0;
            for (int p = ptr[r]; p < ptr[r + 1]; p++) s += val[p] * y[ind[p]];
            ay[r] = s;
        }
        double rpmax = 0.0, mu = 0.0, ymax = 0.0, obj = 0.0, rdmax = 0.0;
        for (k = 0; k < m; k++) {
            int e = ent[k];
            rp[k] = sg[k] * (e >= 0 ? ay[e] : y[-1 - e]) + o[k] - w[k];
            rpmax = fabs(rp[k]) > rpmax ? fabs(rp[k]) : rpmax;
            mu += w[k] * z[k];
        }
        gt_apply(&M, z, gtz);
        for (int j = 0; j < n; j++) {
            rdmax = fabs(cost[j] - gtz[j]) > rdmax ? fabs(cost[j] - gtz[j]) : rdmax;
            ymax = fabs(y[j]) > ymax ? fabs(y[j]) : ymax;
            obj += cost[j] * y[j];
            base[j] = gtz[j] - cost[j];
        }
        if (rpmax <= tol * (1.0 + omax) && rdmax <= tol * (1.0 + cmax) && mu <= tol * (1.0 + fabs(obj))) {
            result = it;
            break;
        }
        if (!(ymax < 1e12)) {
            result = -3;
            break;
        }
        mu /= m;
        /* the normal matrix G^T D G = A^T diag(d_r) A + diag(d_col), d summed over each entity's bounds */
        memset(band, 0, nb * sizeof(double));
        memset(u, 0, (size_t)nr * sizeof(double));
        memset(dcol, 0, (size_t)n * sizeof(double));
        for (k = 0; k < m; k++) {
            iw[k] = 1.0 / w[k];
            D[k] = z[k] * iw[k];
            if (ent[k] >= 0) u[ent[k]] += D[k];
            else dcol[-1 - ent[k]] += D[k];
        }
        for (int r = 0; r < nr; r++) {
            double d = u[r];
            if (d == 0.0) continue;
            for (int p = ptr[r]; p < ptr[r + 1]; p++) { /* each pair of the row's entries once, in any order */
                double dv = d * val[p];
                int a = ind[p];
                for (int q = ptr[r]; q <= p; q++) {
                    int b = ind[q], hi = a > b ? a : b, lo = a > b ? b : a;
                    band[(size_t)(hi - lo) * n + lo] += dv * val[q];
                }
            }
        }
        for (int j = 0; j < n; j++) band[j] += dcol[j] + REGULARISATION;
        if (band_cholesky(n, bw, band) != 0) {
            result = -2;
            break;
        }
        double ap, ad;
        direction(&M, bw, band, base, 0.0, NULL, NULL, iw, w, z, D, rp, dy, dwa, dza, &ap, &ad);
        double mu_aff = 0.0;
        for (k = 0; k < m; k++) mu_aff += (w[k] + ap * dwa[k]) * (z[k] + ad * dza[k]);
        mu_aff /= m;
        double sigma = mu_aff / mu;
        sigma = sigma * sigma * sigma;
        direction(&M, bw, band, base, sigma * mu, dwa, dza, iw, w, z, D, rp, dy, dw, dz, &ap, &ad);
        ap *= share;
        ad *= share;
        for (int j = 0; j < n; j++) y[j] += ap * dy[j];
        for (k = 0; k < m; k++) {
            w[k] += ap * dw[k];
            z[k] += ad * dz[k];
        }
    }
    for (int r = 0; r < nr; r++) { ratio_row[r] = -1.0; upper_row[r] = 0; }
    for (int j = 0; j < n; j++) { ratio_col[j] = -1.0; upper_col[j] = 0; }
    for (k = 0; k < m; k++) {
        double q = z[k] / w[k];
        int e = ent[k];
        double *slot = e >= 0 ? &ratio_row[e] : &ratio_col[-1 - e];
        int *up = e >= 0 ? &upper_row[e] : &upper_col[-1 - e];
        if (q > *slot) { *slot = q; *up = sg[k] < 0.0; }
    }
    free(mem);
    free(ent);
    return result;
}
