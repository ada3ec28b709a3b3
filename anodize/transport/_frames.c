/* The compiled hot path of anodize.transport.codec: decoding runs of small frames.
 *
 * decode_run() is Codec.decode_run in C, to the byte: the same frames are taken, the same
 * tuples appended, the same offset returned, and the same frames (anything but a message
 * whose payload is None or an 8-byte int, with a label already known) are left for the
 * Python decoder, which reports every error. The Python version stays the reference and
 * the fallback: codec.py uses this module only when it was built and ANODIZE_PURE_PYTHON
 * is not set, and the tests run both and compare them on arbitrary bytes.
 *
 * The bytes come from another process, so they are hostile: every length is checked
 * against the end of the buffer before it is used, in arithmetic that cannot overflow.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <stdint.h>
#include <string.h>

#define KIND_MESSAGE 0x4D /* FrameKind.MESSAGE */
#define TAG_NONE 0        /* Tag.NONE */
#define TAG_INT 3         /* Tag.INT */

static uint32_t read_u32(const unsigned char *p)
{
    return (uint32_t)p[0] | ((uint32_t)p[1] << 8) | ((uint32_t)p[2] << 16) | ((uint32_t)p[3] << 24);
}

static int64_t read_i64(const unsigned char *p)
{
    uint64_t value = 0;
    for (int i = 7; i >= 0; i--) {
        value = (value << 8) | p[i];
    }
    return (int64_t)value; /* two's complement, as struct's "<q" */
}

/* decode_run(buffer, at, names, into) -> int: see Codec.decode_run. */
static PyObject *decode_run(PyObject *module, PyObject *const *args, Py_ssize_t nargs)
{
    (void)module;
    if (nargs != 4) {
        PyErr_Format(PyExc_TypeError, "decode_run() takes 4 arguments (%zd given)", nargs);
        return NULL;
    }
    PyObject *names = args[2];
    if (!PyDict_Check(names)) {
        PyErr_SetString(PyExc_TypeError, "decode_run(): names must be a dict");
        return NULL;
    }
    Py_ssize_t at = PyLong_AsSsize_t(args[1]);
    if (at == -1 && PyErr_Occurred()) {
        return NULL;
    }
    if (at < 0) {
        PyErr_SetString(PyExc_ValueError, "decode_run(): the offset must not be negative");
        return NULL;
    }
    PyObject *append = PyObject_GetAttrString(args[3], "append");
    if (append == NULL) {
        return NULL;
    }
    Py_buffer view;
    if (PyObject_GetBuffer(args[0], &view, PyBUF_SIMPLE) != 0) {
        Py_DECREF(append);
        return NULL;
    }
    const unsigned char *data = (const unsigned char *)view.buf;
    const Py_ssize_t size = view.len;
    PyObject *raw = NULL;   /* the last label's bytes, and its name: a stream repeats a label */
    PyObject *label = NULL; /* borrowed from names, which the caller keeps alive */
    int failed = 0;
    while (size - at >= 4) {
        const Py_ssize_t length = (Py_ssize_t)read_u32(data + at);
        if (length > size - at - 4 || length < 6 || data[at + 4] != KIND_MESSAGE) {
            break; /* incomplete, too short for kind, label size and tag, or not a message */
        }
        const Py_ssize_t end = at + 4 + length;
        const Py_ssize_t label_length = (Py_ssize_t)read_u32(data + at + 5);
        if (label_length > end - at - 9) {
            break; /* the label runs past the frame: the Python decoder reports it */
        }
        const Py_ssize_t start = at + 9 + label_length;
        const unsigned char *label_bytes = data + at + 9;
        if (raw == NULL || PyBytes_GET_SIZE(raw) != label_length
                || memcmp(PyBytes_AS_STRING(raw), label_bytes, (size_t)label_length) != 0) {
            Py_XDECREF(raw);
            raw = PyBytes_FromStringAndSize((const char *)label_bytes, label_length);
            if (raw == NULL) {
                failed = 1;
                break;
            }
            label = PyDict_GetItemWithError(names, raw);
            if (label == NULL) {
                failed = PyErr_Occurred() != NULL;
                break; /* a label not seen yet: decode_body learns it */
            }
        }
        PyObject *payload;
        if (end == start + 1 && data[start] == TAG_NONE) {
            payload = Py_NewRef(Py_None);
        } else if (end == start + 9 && data[start] == TAG_INT) {
            payload = PyLong_FromLongLong((long long)read_i64(data + start + 1));
            if (payload == NULL) {
                failed = 1;
                break;
            }
        } else {
            break;
        }
        PyObject *message = PyTuple_New(2);
        PyObject *frame_size = PyLong_FromSsize_t(4 + length);
        PyObject *entry = PyTuple_New(2);
        if (message == NULL || frame_size == NULL || entry == NULL) {
            Py_XDECREF(message);
            Py_XDECREF(frame_size);
            Py_XDECREF(entry);
            Py_DECREF(payload);
            failed = 1;
            break;
        }
        PyTuple_SET_ITEM(message, 0, Py_NewRef(label));
        PyTuple_SET_ITEM(message, 1, payload);
        PyTuple_SET_ITEM(entry, 0, message);
        PyTuple_SET_ITEM(entry, 1, frame_size);
        PyObject *appended = PyObject_CallOneArg(append, entry);
        Py_DECREF(entry);
        if (appended == NULL) {
            failed = 1;
            break;
        }
        Py_DECREF(appended);
        at = end;
    }
    Py_XDECREF(raw);
    PyBuffer_Release(&view);
    Py_DECREF(append);
    if (failed) {
        return NULL;
    }
    return PyLong_FromSsize_t(at);
}

static PyMethodDef methods[] = {
    {"decode_run", (PyCFunction)(void (*)(void))decode_run, METH_FASTCALL,
     "decode_run(buffer, at, names, into) -> int\n\nCodec.decode_run in C (see anodize.transport.codec)."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef frames_module = {
    PyModuleDef_HEAD_INIT, "_frames",
    "The compiled hot path of anodize.transport.codec (a pure-Python fallback stays).", -1, methods,
    NULL, NULL, NULL, NULL,
};

PyMODINIT_FUNC PyInit__frames(void)
{
    return PyModule_Create(&frames_module);
}
