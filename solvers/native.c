/* Per-point kernels of the solvers package, compiled and loaded by solvers/native.py (geometry/native.py's
 * loader); the numpy paths compute the same operations in the same order (tests/solvers/test_native.py). */
#include <math.h>

/* numpy's maximum: NaN if either argument is NaN */
static double np_max(double a, double b) { return isnan(a) ? a : (isnan(b) ? b : (a > b ? a : (a < b ? b : a))); }
static double np_min(double a, double b) { return isnan(a) ? a : (isnan(b) ? b : (a < b ? a : (a > b ? b : a))); }

/* PieceProfile.h_local (solvers/timing.py) inside the piece: dt/dx = d / sqrt(q) at x = x0 + xl[m], q the uniform
 * quadratic B-spline of the n knot intervals' control points c (n + 2) in its basis form (bspline.value). */
void fs_h_local(int n, double d, const double *c, int x0, int K, const double *xl_in, double *out) {
    for (int m = 0; m < K; m++) {
        double xl = np_min(np_max(xl_in[m], -(double)x0), (double)(n - x0));
        double fl = floor(xl);
        long long k = isnan(fl) ? 0 : (long long)fl + x0;
        if (k < 0) k = 0;
        if (k > n - 1) k = n - 1;
        double t = xl - (double)(k - x0);
        double u = 1.0 - t;
        double v = 0.5 * (c[k] * u * u + c[k + 1] * (1.0 + 2.0 * t * u) + c[k + 2] * t * t);
        out[m] = d / sqrt(np_max(v, 0.0));
    }
}
