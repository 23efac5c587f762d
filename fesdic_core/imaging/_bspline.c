/* Fused evaluation of the B-spline image interpolants: value and exact gradient (or the
 * value alone: ``grad`` NULL, half the arithmetic), bicubic (``evaluate``, 4x4 support) and
 * biquintic (``evaluate5``, 6x6 support).
 *
 * The compiled twins of fesdic_core.imaging.image._evaluate_numpy and fesdic_core.imaging.bspline5.evaluate_numpy
 * (same arithmetic, one pass per point, the coefficient support read row by row from a
 * padded coefficient array). Pixel coordinates (x, y) = (column, row), pixel centres at
 * integers; coordinates are folded into [0, n - 1] by the mirror symmetry of the spline
 * ("mirror" boundary), and the derivative picks up the sign of the fold. Non-finite
 * coordinates give NaN. The padding must be >= 2 (cubic: nodes i-1 .. i+2) or >= 3
 * (quintic: nodes i-2 .. i+3).
 *
 * It only needs Python.h: arrays arrive through the buffer protocol (C-contiguous float64,
 * checked by the Python wrappers), and the GIL is released during the loop so that callers
 * may split the points over threads.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>

static inline double fold(double x, Py_ssize_t n, double *sign)
{
    if (n == 1) { *sign = 0.0; return 0.0; }
    if (x >= 0.0 && x <= (double)(n - 1)) { *sign = 1.0; return x; }   /* inside: no fold */
    const double period = 2.0 * (double)(n - 1);
    double xm = fmod(x, period);
    if (xm < 0.0) xm += period;
    if (xm > (double)(n - 1)) { *sign = -1.0; return period - xm; }
    *sign = 1.0;
    return xm;
}

/* Cubic B-spline weights of the nodes i-1 .. i+2 at i + t, and their derivatives. */
static inline void cubic_weights(double t, double w[4], double dw[4])
{
    const double s = 1.0 - t, t2 = t * t, t3 = t2 * t;
    w[0] = s * s * s * (1.0 / 6.0);
    w[1] = (3.0 * t3 - 6.0 * t2 + 4.0) * (1.0 / 6.0);
    w[2] = (-3.0 * t3 + 3.0 * t2 + 3.0 * t + 1.0) * (1.0 / 6.0);
    w[3] = t3 * (1.0 / 6.0);
    dw[0] = -0.5 * s * s;
    dw[1] = 0.5 * (3.0 * t2 - 4.0 * t);
    dw[2] = 0.5 * (-3.0 * t2 + 2.0 * t + 1.0);
    dw[3] = 0.5 * t2;
}

/* Quintic B-spline weights of the nodes i-2 .. i+3 at i + t (t in [0, 1]), and their
 * derivatives: b5 of the distances t+2, t+1, t, 1-t, 2-t, 3-t, expanded in t (x 1/120). */
static inline void quintic_weights(double t, double w[6], double dw[6])
{
    const double s = 1.0 - t, s2 = s * s, t2 = t * t, t4 = t2 * t2;
    const double c = 1.0 / 120.0;
    w[0] = s2 * s2 * s * c;
    w[1] = (26.0 + t * (-50.0 + t * (20.0 + t * (20.0 + t * (-20.0 + t * 5.0))))) * c;
    w[2] = (66.0 + t2 * (-60.0 + t2 * (30.0 - 10.0 * t))) * c;
    w[3] = (26.0 + t * (50.0 + t * (20.0 + t * (-20.0 + t * (-20.0 + t * 10.0))))) * c;
    w[4] = (1.0 + t * (5.0 + t * (10.0 + t * (10.0 + t * (5.0 - 5.0 * t))))) * c;
    w[5] = t4 * t * c;
    dw[0] = -5.0 * s2 * s2 * c;
    dw[1] = (-50.0 + t * (40.0 + t * (60.0 + t * (-80.0 + t * 25.0)))) * c;
    dw[2] = t * (-120.0 + t2 * (120.0 - 50.0 * t)) * c;
    dw[3] = (50.0 + t * (40.0 + t * (-60.0 + t * (-80.0 + t * 50.0)))) * c;
    dw[4] = (5.0 + t * (20.0 + t * (30.0 + t * (20.0 - 25.0 * t)))) * c;
    dw[5] = 5.0 * t4 * c;
}

static void evaluate3(const double *padded, Py_ssize_t h, Py_ssize_t w, Py_ssize_t pad,
                      const double *xy, Py_ssize_t n, double *value, double *grad)
{
    const Py_ssize_t pw = w + 2 * pad;
    for (Py_ssize_t k = 0; k < n; ++k) {
        const double x = xy[2 * k], y = xy[2 * k + 1];
        if (!isfinite(x) || !isfinite(y)) {
            value[k] = NAN;
            if (grad) grad[2 * k] = grad[2 * k + 1] = NAN;
            continue;
        }
        double sx, sy, wx[4], dwx[4], wy[4], dwy[4];
        const double xf = fold(x, w, &sx), yf = fold(y, h, &sy);
        const double j = floor(xf), i = floor(yf);
        cubic_weights(xf - j, wx, dwx);
        cubic_weights(yf - i, wy, dwy);
        const double *c = padded + ((Py_ssize_t)i + pad - 1) * pw + (Py_ssize_t)j + pad - 1;
        double v = 0.0, gx = 0.0, gy = 0.0;
        if (!grad) {
            for (int a = 0; a < 4; ++a, c += pw)
                v += wy[a] * (c[0] * wx[0] + c[1] * wx[1] + c[2] * wx[2] + c[3] * wx[3]);
            value[k] = v;
            continue;
        }
        for (int a = 0; a < 4; ++a, c += pw) {
            const double cx = c[0] * wx[0] + c[1] * wx[1] + c[2] * wx[2] + c[3] * wx[3];
            const double cdx = c[0] * dwx[0] + c[1] * dwx[1] + c[2] * dwx[2] + c[3] * dwx[3];
            v += wy[a] * cx;
            gx += wy[a] * cdx;
            gy += dwy[a] * cx;
        }
        value[k] = v;
        grad[2 * k] = sx * gx;
        grad[2 * k + 1] = sy * gy;
    }
}

static void evaluate5(const double *padded, Py_ssize_t h, Py_ssize_t w, Py_ssize_t pad,
                      const double *xy, Py_ssize_t n, double *value, double *grad)
{
    const Py_ssize_t pw = w + 2 * pad;
    for (Py_ssize_t k = 0; k < n; ++k) {
        const double x = xy[2 * k], y = xy[2 * k + 1];
        if (!isfinite(x) || !isfinite(y)) {
            value[k] = NAN;
            if (grad) grad[2 * k] = grad[2 * k + 1] = NAN;
            continue;
        }
        double sx, sy, wx[6], dwx[6], wy[6], dwy[6];
        const double xf = fold(x, w, &sx), yf = fold(y, h, &sy);
        const double j = floor(xf), i = floor(yf);
        quintic_weights(xf - j, wx, dwx);
        quintic_weights(yf - i, wy, dwy);
        const double *c = padded + ((Py_ssize_t)i + pad - 2) * pw + (Py_ssize_t)j + pad - 2;
        double v = 0.0, gx = 0.0, gy = 0.0;
        if (!grad) {
            for (int a = 0; a < 6; ++a, c += pw)
                v += wy[a] * (c[0] * wx[0] + c[1] * wx[1] + c[2] * wx[2] + c[3] * wx[3]
                              + c[4] * wx[4] + c[5] * wx[5]);
            value[k] = v;
            continue;
        }
        for (int a = 0; a < 6; ++a, c += pw) {
            const double cx = c[0] * wx[0] + c[1] * wx[1] + c[2] * wx[2] + c[3] * wx[3]
                              + c[4] * wx[4] + c[5] * wx[5];
            const double cdx = c[0] * dwx[0] + c[1] * dwx[1] + c[2] * dwx[2] + c[3] * dwx[3]
                               + c[4] * dwx[4] + c[5] * dwx[5];
            v += wy[a] * cx;
            gx += wy[a] * cdx;
            gy += dwy[a] * cx;
        }
        value[k] = v;
        grad[2 * k] = sx * gx;
        grad[2 * k + 1] = sy * gy;
    }
}

typedef void (*kernel)(const double *, Py_ssize_t, Py_ssize_t, Py_ssize_t, const double *,
                       Py_ssize_t, double *, double *);

/* The Python call of a kernel: checks the buffers' sizes, runs it without the GIL. */
static PyObject *call(PyObject *args, kernel evaluate, Py_ssize_t min_pad, const char *name)
{
    Py_buffer padded, xy, value, grad = {0};
    Py_ssize_t h, w, pad;
    PyObject *grad_object;
    if (!PyArg_ParseTuple(args, "y*nnny*w*O", &padded, &h, &w, &pad, &xy, &value, &grad_object))
        return NULL;
    const int with_grad = grad_object != Py_None;
    if (with_grad && PyObject_GetBuffer(grad_object, &grad, PyBUF_WRITABLE) < 0) {
        PyBuffer_Release(&padded);
        PyBuffer_Release(&xy);
        PyBuffer_Release(&value);
        return NULL;
    }
    PyObject *result = NULL;
    const Py_ssize_t n = xy.len / (Py_ssize_t)(2 * sizeof(double));
    if (h < 1 || w < 1 || pad < min_pad) {
        PyErr_Format(PyExc_ValueError, "%s: need h, w >= 1 and pad >= %zd", name, min_pad);
    } else if (padded.len != (Py_ssize_t)sizeof(double) * (h + 2 * pad) * (w + 2 * pad)) {
        PyErr_Format(PyExc_ValueError, "%s: padded coefficients of the wrong size", name);
    } else if (xy.len % (Py_ssize_t)(2 * sizeof(double)) != 0
               || value.len != (Py_ssize_t)sizeof(double) * n
               || (with_grad && grad.len != (Py_ssize_t)(2 * sizeof(double)) * n)) {
        PyErr_Format(PyExc_ValueError, "%s: xy (n, 2), value (n,), grad (n, 2) mismatch", name);
    } else {
        Py_BEGIN_ALLOW_THREADS
        evaluate((const double *)padded.buf, h, w, pad, (const double *)xy.buf, n,
                 (double *)value.buf, with_grad ? (double *)grad.buf : NULL);
        Py_END_ALLOW_THREADS
        result = Py_None;
        Py_INCREF(result);
    }
    PyBuffer_Release(&padded);
    PyBuffer_Release(&xy);
    PyBuffer_Release(&value);
    if (with_grad)
        PyBuffer_Release(&grad);
    return result;
}

static PyObject *py_evaluate(PyObject *self, PyObject *args)
{
    return call(args, evaluate3, 2, "_bspline.evaluate");
}

static PyObject *py_evaluate5(PyObject *self, PyObject *args)
{
    return call(args, evaluate5, 3, "_bspline.evaluate5");
}

static PyMethodDef methods[] = {
    {"evaluate", py_evaluate, METH_VARARGS,
     "evaluate(padded, h, w, pad, xy, value, grad): bicubic B-spline value and gradient "
     "(C-contiguous float64 buffers; value and grad are written; grad None: the value only)."},
    {"evaluate5", py_evaluate5, METH_VARARGS,
     "evaluate5(padded, h, w, pad, xy, value, grad): the same for the biquintic B-spline."},
    {NULL, NULL, 0, NULL}};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_bspline",
                                    "Fused bicubic and biquintic B-spline interpolation (value and gradient).",
                                    -1, methods};

PyMODINIT_FUNC PyInit__bspline(void) { return PyModule_Create(&module); }
