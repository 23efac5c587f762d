/* Fused evaluation of a bicubic B-spline image interpolant: value and exact gradient
 * (or the value alone: ``grad`` NULL, half the arithmetic).
 *
 * The compiled twin of fesdic_core.image._evaluate_numpy (same arithmetic, one pass per
 * point, the 4x4 coefficient support read row by row from a padded coefficient array).
 * Pixel coordinates (x, y) = (column, row), pixel centres at integers; coordinates are
 * folded into [0, n - 1] by the mirror symmetry of the spline ("mirror" boundary), and the
 * derivative picks up the sign of the fold. Non-finite coordinates give NaN.
 *
 * It only needs Python.h: arrays arrive through the buffer protocol (C-contiguous float64,
 * checked by the Python wrapper), and the GIL is released during the loop so that callers
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

static void evaluate(const double *padded, Py_ssize_t h, Py_ssize_t w, Py_ssize_t pad,
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

static PyObject *py_evaluate(PyObject *self, PyObject *args)
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
    if (h < 1 || w < 1 || pad < 2) {
        PyErr_SetString(PyExc_ValueError, "_bspline.evaluate: need h, w >= 1 and pad >= 2");
    } else if (padded.len != (Py_ssize_t)sizeof(double) * (h + 2 * pad) * (w + 2 * pad)) {
        PyErr_SetString(PyExc_ValueError, "_bspline.evaluate: padded coefficients of the wrong size");
    } else if (xy.len % (Py_ssize_t)(2 * sizeof(double)) != 0
               || value.len != (Py_ssize_t)sizeof(double) * n
               || (with_grad && grad.len != (Py_ssize_t)(2 * sizeof(double)) * n)) {
        PyErr_SetString(PyExc_ValueError, "_bspline.evaluate: xy (n, 2), value (n,), grad (n, 2) mismatch");
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

static PyMethodDef methods[] = {
    {"evaluate", py_evaluate, METH_VARARGS,
     "evaluate(padded, h, w, pad, xy, value, grad): bicubic B-spline value and gradient "
     "(C-contiguous float64 buffers; value and grad are written; grad None: the value only)."},
    {NULL, NULL, 0, NULL}};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_bspline",
                                    "Fused bicubic B-spline interpolation (value and gradient).",
                                    -1, methods};

PyMODINIT_FUNC PyInit__bspline(void) { return PyModule_Create(&module); }
