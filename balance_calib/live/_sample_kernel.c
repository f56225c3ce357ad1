/* The live calibrator's lone sample in one C call: serialized balance/raw sample in, serialized
 * balance/wrench and balance/wrench_uncertainty out (live/sample_kernel.py says when it applies).
 *
 * The pure core's vectorised path (calibrator_core.compute_wrench, stream.wrench_uncertainty)
 * is the specification; this is its only accelerator, for one sample of a direct polynomial
 * model of the bridge outputs, the same steps in the same order (called by
 * stream.LiveCalibrator.process_messages for the samples it takes); test/test_sample_kernel.py
 * holds the two to 1e-12:
 *
 *   x      = outputs * input_scale - zero                     electrical zero, output space (TM-663 §5)
 *   d_t    = prod over the term's columns of [x, 1]           design row, eqs. (1)-(18)
 *   L_k    = sum_t C_kt d_t                                   loads, balance axes (constant-free, §10.1)
 *   W_i    = sign_i (L - tare)_perm_i                         tunnel axes, §10.2
 *   u_k    = sqrt(s_k^2 (1 + d V d) + t_k^2)                  standard uncertainty (GUM, k = 1)
 *   r_k    = |L_k| / capacity_k                               overload: peak noted, r_k > fraction reported
 *
 * Anything else -- a byte layout it does not know, a non-finite or saturated output, a load that is
 * not finite -- returns None and the pure core handles the sample (and says why). The plan (a
 * capsule made by plan()) is immutable; the caller makes a new one when the calibration, zero, tare,
 * input scale or frame_id changes. The only state written is the caller's peak array (the overload
 * monitor's peak fraction per component). The GIL is held throughout (a few microseconds).
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdint.h>
#include <string.h>

#define CAPSULE_NAME "balance_calib.live._sample_kernel.Plan"

typedef struct {
    double scale;
    double zero[6];
    double output_range[6];
    double envelope[6];
    double capacity[6];       /* rated load per component (inf where the calibration lacks it) */
    double tare[6];
    int perm[6];
    double signs[6];
    Py_ssize_t n_terms, width;
    Py_ssize_t *index;        /* (n_terms, width) into x[0..5], 6 = the constant 1 */
    double *coefficients;     /* (6, n_terms) */
    double *covariance;       /* V's upper triangle, packed by rows: V_ii, then V_ij + V_ji for j > i
                                 (half the bytes to fetch with cold caches); NULL: no uncertainty */
    double sigma2[6];         /* residual sigma^2 per component (0 where the model lacks it) */
    double tare2[6];          /* tare sigma^2 */
    int has_component[6];     /* the model gives this component (else its uncertainty is NaN) */
    char *middle;             /* frame_id length, characters and padding of the output messages */
    Py_ssize_t middle_size;
} Plan;

static PyObject *lone(const Plan *plan, const char *data, Py_ssize_t size, int want_uncertainty, double fraction,
                      double *peak);

static void plan_free(PyObject *capsule)
{
    Plan *plan = (Plan *)PyCapsule_GetPointer(capsule, CAPSULE_NAME);
    if (plan == NULL) {
        PyErr_Clear();
        return;
    }
    PyMem_Free(plan->index);
    PyMem_Free(plan->coefficients);
    PyMem_Free(plan->covariance);
    PyMem_Free(plan->middle);
    PyMem_Free(plan);
}

/* Copy a contiguous buffer of `count` items of `itemsize` bytes (format checked by the caller's
 * numpy dtype: float64 or intp) into `out`. */
static int copy_buffer(PyObject *object, void *out, Py_ssize_t count, Py_ssize_t itemsize, const char *name)
{
    Py_buffer view;
    if (PyObject_GetBuffer(object, &view, PyBUF_C_CONTIGUOUS) < 0)
        return -1;
    if (view.len != count * itemsize) {
        PyErr_Format(PyExc_ValueError, "%s: %zd bytes, expected %zd", name, view.len, count * itemsize);
        PyBuffer_Release(&view);
        return -1;
    }
    memcpy(out, view.buf, (size_t)view.len);
    PyBuffer_Release(&view);
    return 0;
}

static PyObject *make_plan(PyObject *self, PyObject *args)
{
    (void)self;
    double scale;
    PyObject *zero, *output_range, *envelope, *capacity, *tare, *perm, *signs, *index, *coefficients;
    PyObject *covariance, *sigma2, *tare2, *has_component, *middle;
    Py_ssize_t n_terms, width;
    if (!PyArg_ParseTuple(args, "dOOOOOOOnnOOOOOOS:plan", &scale, &zero, &output_range, &envelope, &capacity,
                          &tare, &perm,
                          &signs, &n_terms, &width, &index, &coefficients, &covariance, &sigma2, &tare2,
                          &has_component, &middle))
        return NULL;
    if (n_terms <= 0 || width <= 0 || n_terms > 100000 || width > 16) {
        PyErr_SetString(PyExc_ValueError, "plan: n_terms or width out of range");
        return NULL;
    }
    Plan *plan = PyMem_Calloc(1, sizeof(Plan));
    if (plan == NULL)
        return PyErr_NoMemory();
    PyObject *capsule = PyCapsule_New(plan, CAPSULE_NAME, plan_free);
    if (capsule == NULL) {
        PyMem_Free(plan);
        return NULL;
    }
    int64_t perm64[6], has64[6];
    plan->scale = scale;
    plan->n_terms = n_terms;
    plan->width = width;
    plan->index = PyMem_Malloc(sizeof(Py_ssize_t) * n_terms * width);
    plan->coefficients = PyMem_Malloc(sizeof(double) * 6 * n_terms);
    plan->middle_size = PyBytes_GET_SIZE(middle);
    plan->middle = PyMem_Malloc((size_t)plan->middle_size + 1);
    if (plan->index == NULL || plan->coefficients == NULL || plan->middle == NULL) {
        Py_DECREF(capsule);
        return PyErr_NoMemory();
    }
    memcpy(plan->middle, PyBytes_AS_STRING(middle), (size_t)plan->middle_size);
    if (copy_buffer(zero, plan->zero, 6, sizeof(double), "zero") < 0 ||
        copy_buffer(output_range, plan->output_range, 6, sizeof(double), "output_range") < 0 ||
        copy_buffer(envelope, plan->envelope, 6, sizeof(double), "envelope") < 0 ||
        copy_buffer(capacity, plan->capacity, 6, sizeof(double), "capacity") < 0 ||
        copy_buffer(tare, plan->tare, 6, sizeof(double), "tare") < 0 ||
        copy_buffer(perm, perm64, 6, sizeof(int64_t), "permutation") < 0 ||
        copy_buffer(signs, plan->signs, 6, sizeof(double), "signs") < 0 ||
        copy_buffer(index, plan->index, n_terms * width, sizeof(Py_ssize_t), "index") < 0 ||
        copy_buffer(coefficients, plan->coefficients, 6 * n_terms, sizeof(double), "coefficients") < 0 ||
        copy_buffer(sigma2, plan->sigma2, 6, sizeof(double), "sigma2") < 0 ||
        copy_buffer(tare2, plan->tare2, 6, sizeof(double), "tare2") < 0 ||
        copy_buffer(has_component, has64, 6, sizeof(int64_t), "has_component") < 0) {
        Py_DECREF(capsule);
        return NULL;
    }
    for (int i = 0; i < 6; i++) {
        if (perm64[i] < 0 || perm64[i] > 5) {
            Py_DECREF(capsule);
            PyErr_SetString(PyExc_ValueError, "plan: permutation out of range");
            return NULL;
        }
        plan->perm[i] = (int)perm64[i];
        plan->has_component[i] = has64[i] != 0;
    }
    for (Py_ssize_t k = 0; k < n_terms * width; k++) {
        if (plan->index[k] < 0 || plan->index[k] > 6) {
            Py_DECREF(capsule);
            PyErr_SetString(PyExc_ValueError, "plan: term index out of range");
            return NULL;
        }
    }
    if (covariance != Py_None) {
        double *full = PyMem_Malloc(sizeof(double) * n_terms * n_terms);
        plan->covariance = PyMem_Malloc(sizeof(double) * (n_terms * (n_terms + 1) / 2));
        if (full == NULL || plan->covariance == NULL) {
            PyMem_Free(full);
            Py_DECREF(capsule);
            return PyErr_NoMemory();
        }
        if (copy_buffer(covariance, full, n_terms * n_terms, sizeof(double), "covariance") < 0) {
            PyMem_Free(full);
            Py_DECREF(capsule);
            return NULL;
        }
        double *packed = plan->covariance;
        for (Py_ssize_t i = 0; i < n_terms; i++) {
            *packed++ = full[i * n_terms + i];
            for (Py_ssize_t j = i + 1; j < n_terms; j++)
                *packed++ = full[i * n_terms + j] + full[j * n_terms + i];
        }
        PyMem_Free(full);
    }
    return capsule;
}

/* bytes of a WrenchStamped: encapsulation, stamp, the plan's frame_id and padding, six doubles */
static PyObject *encode(const Plan *plan, int32_t sec, uint32_t nanosec, const double values[6])
{
    Py_ssize_t size = 12 + plan->middle_size + 48;
    PyObject *out = PyBytes_FromStringAndSize(NULL, size);
    if (out == NULL)
        return NULL;
    char *p = PyBytes_AS_STRING(out);
    static const char header[4] = {0, 1, 0, 0};
    memcpy(p, header, 4);
    memcpy(p + 4, &sec, 4);
    memcpy(p + 8, &nanosec, 4);
    memcpy(p + 12, plan->middle, (size_t)plan->middle_size);
    memcpy(p + 12 + plan->middle_size, values, 48);
    return out;
}

static PyObject *run(PyObject *self, PyObject *args)
{
    (void)self;
    PyObject *capsule;
    const char *data;
    Py_ssize_t size;
    int want_uncertainty;
    double fraction;
    Py_buffer peak_view;
    if (!PyArg_ParseTuple(args, "Oy#pdw*:run", &capsule, &data, &size, &want_uncertainty, &fraction, &peak_view))
        return NULL;
    PyObject *result = NULL;
    const Plan *plan = (const Plan *)PyCapsule_GetPointer(capsule, CAPSULE_NAME);
    if (plan == NULL)
        goto done;
    if (peak_view.len != 6 * (Py_ssize_t)sizeof(double) || !PyBuffer_IsContiguous(&peak_view, 'C')) {
        PyErr_SetString(PyExc_ValueError, "run: peak must be 6 contiguous float64");
        goto done;
    }
    result = lone(plan, data, size, want_uncertainty, fraction, (double *)peak_view.buf);
done:
    PyBuffer_Release(&peak_view);
    return result;
}

static PyObject *lone(const Plan *plan, const char *data, Py_ssize_t size, int want_uncertainty, double fraction,
                      double *peak)
{
    /* XCDR1 little endian (raw_codec.py): header, int32 sec, uint32 nanosec, uint32 frame length with
     * its NUL, the characters, padding to 8 after the header, six float64 */
    if (size < 64 || memcmp(data, "\x00\x01\x00\x00", 4) != 0)
        Py_RETURN_NONE;
    uint32_t frame_length;
    memcpy(&frame_length, data + 12, 4);
    if (frame_length < 1 || frame_length > (uint32_t)size)
        Py_RETURN_NONE;
    Py_ssize_t offset = 4 + (12 + (Py_ssize_t)frame_length + 7) / 8 * 8;
    if (offset + 48 != size)
        Py_RETURN_NONE;
    int32_t sec;
    uint32_t nanosec;
    memcpy(&sec, data + 4, 4);
    memcpy(&nanosec, data + 8, 4);
    double raw[6], x[7];
    memcpy(raw, data + offset, 48);
    for (int i = 0; i < 6; i++) {
        double v = plan->scale == 1.0 ? raw[i] : raw[i] * plan->scale;
        if (!isfinite(v) || fabs(v) > plan->output_range[i] || fabs(v) >= 1e30)
            Py_RETURN_NONE;             /* rejected, saturated or huge: the pure core says why */
        x[i] = v - plan->zero[i];
    }
    x[6] = 1.0;
    Py_ssize_t n = plan->n_terms, width = plan->width;
    double design_stack[128];
    double *design = n <= 128 ? design_stack : PyMem_Malloc(sizeof(double) * n);
    if (design == NULL)
        return PyErr_NoMemory();
    for (Py_ssize_t t = 0; t < n; t++) {
        const Py_ssize_t *columns = plan->index + t * width;
        double product = x[columns[0]];
        for (Py_ssize_t w = 1; w < width; w++)
            product *= x[columns[w]];
        design[t] = product;
    }
    double loads[6], tared[6], wrench[6];
    int outside = 0, finite = 1;
    for (int k = 0; k < 6; k++) {
        const double *row = plan->coefficients + k * n;
        double sum = 0.0;
        for (Py_ssize_t t = 0; t < n; t++)
            sum += row[t] * design[t];
        loads[k] = sum;
        finite &= isfinite(sum) != 0;
        outside |= fabs(sum) > plan->envelope[k];
        tared[k] = sum - plan->tare[k];
    }
    if (!finite) {
        if (design != design_stack)
            PyMem_Free(design);
        Py_RETURN_NONE;
    }
    int exceeds = 0;
    for (int k = 0; k < 6; k++) {
        double ratio = fabs(loads[k]) / plan->capacity[k];
        if (ratio > peak[k])
            peak[k] = ratio;
        exceeds |= ratio > fraction;
    }
    for (int i = 0; i < 6; i++)
        wrench[i] = tared[plan->perm[i]] * plan->signs[i];
    PyObject *uncertainty_bytes = NULL;
    if (want_uncertainty && plan->covariance != NULL) {
        double h = 0.0;              /* d V d over the packed triangle, read once front to back */
        const double *packed = plan->covariance;
        for (Py_ssize_t i = 0; i < n; i++) {
            double row = *packed++ * design[i];
            for (Py_ssize_t j = i + 1; j < n; j++)
                row += *packed++ * design[j];
            h += row * design[i];
        }
        double u[6], tunnel[6];
        for (int k = 0; k < 6; k++)
            u[k] = plan->has_component[k] ? sqrt(plan->sigma2[k] * (1.0 + h) + plan->tare2[k]) : NAN;
        for (int i = 0; i < 6; i++)
            tunnel[i] = fabs(u[plan->perm[i]] * plan->signs[i]);
        uncertainty_bytes = encode(plan, sec, nanosec, tunnel);
    }
    if (design != design_stack)
        PyMem_Free(design);
    if (want_uncertainty && plan->covariance != NULL && uncertainty_bytes == NULL)
        return NULL;
    PyObject *wrench_bytes = encode(plan, sec, nanosec, wrench);
    if (wrench_bytes == NULL) {
        Py_XDECREF(uncertainty_bytes);
        return NULL;
    }
    if (uncertainty_bytes == NULL) {
        uncertainty_bytes = Py_None;
        Py_INCREF(Py_None);
    }
    long long stamp_ns = (long long)sec * 1000000000LL + (long long)nanosec;
    return Py_BuildValue("(Ly#(dddddd)OONN)", stamp_ns, data + 16, (Py_ssize_t)(frame_length - 1),
                         loads[0], loads[1], loads[2], loads[3], loads[4], loads[5],
                         outside ? Py_True : Py_False, exceeds ? Py_True : Py_False, wrench_bytes, uncertainty_bytes);
}

static PyMethodDef methods[] = {
    {"plan", make_plan, METH_VARARGS,
     "plan(scale, zero, output_range, envelope, capacity, tare, permutation, signs, n_terms, width, index, "
     "coefficients, covariance|None, sigma2, tare2, has_component, middle) -> capsule"},
    {"run", run, METH_VARARGS,
     "run(plan, data: bytes, want_uncertainty, overload_fraction, peak (6,) float64, updated) -> None | "
     "(stamp_ns, frame_id bytes, loads (6,) balance axes before the tare, outside the envelope, "
     "beyond overload_fraction, wrench bytes, uncertainty bytes | None)"},
    {NULL, NULL, 0, NULL}};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_sample_kernel",
                                    "The live calibrator's lone sample in C (see live/sample_kernel.py).", -1,
                                    methods, NULL, NULL, NULL, NULL};

PyMODINIT_FUNC PyInit__sample_kernel(void)
{
#if defined(__BYTE_ORDER__) && __BYTE_ORDER__ != __ORDER_LITTLE_ENDIAN__
    PyErr_SetString(PyExc_ImportError, "_sample_kernel reads little-endian CDR with memcpy: a little-endian host only");
    return NULL;
#endif
    return PyModule_Create(&module);
}
