/* The compiled hot path of the process transport: decoding runs of small frames (receiver)
 * and writing the commonest frames (sender).
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
#include <pythread.h>
#include <errno.h>
#include <limits.h>
#include <stdint.h>
#include <string.h>
#include <structmember.h>
#include <sys/uio.h>
#include <unistd.h>

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
    PyObject *label = NULL; /* a strong reference: append() may run code that changes names */
    int failed = 0;
    while (size - at >= 4) {
        /* Lengths compared as unsigned 64-bit numbers: a 32-bit Py_ssize_t cannot hold them all. */
        const uint64_t length = read_u32(data + at);
        if (length > (uint64_t)(size - at - 4) || length < 6 || data[at + 4] != KIND_MESSAGE) {
            break; /* incomplete, too short for kind, label size and tag, or not a message */
        }
        const Py_ssize_t end = at + 4 + (Py_ssize_t)length;
        const uint64_t label_bytes_left = length - 5; /* after kind and label size: at least 1 */
        if ((uint64_t)read_u32(data + at + 5) > label_bytes_left) {
            break; /* the label runs past the frame: the Python decoder reports it */
        }
        const Py_ssize_t label_length = (Py_ssize_t)read_u32(data + at + 5);
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
            PyObject *found = PyDict_GetItemWithError(names, raw);
            Py_XSETREF(label, Py_XNewRef(found));
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
        PyObject *frame_size = PyLong_FromSsize_t(4 + (Py_ssize_t)length);
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
    Py_XDECREF(label);
    PyBuffer_Release(&view);
    Py_DECREF(append);
    if (failed) {
        return NULL;
    }
    return PyLong_FromSsize_t(at);
}


/* ---- the shared-memory byte ring (anodize/_transport/ring.py documents the layout and the
 * protocol; ring_write_python and ring_read_python are the reference, to the byte). The indices
 * come from another process: every use checks 0 <= tail - head <= capacity first, and every
 * position is taken modulo the capacity, so no index the peer writes reaches outside the data. */
#define RING_HEADER 4096
#define RING_TAIL 0
#define RING_HEAD 64
#define RING_SLEEPING 128
#define RING_WAITING 192
#define RING_CLOSED 256

static uint64_t *ring_u64(unsigned char *ring, int offset)
{
    return (uint64_t *)(void *)(ring + offset);
}

static uint32_t *ring_u32(unsigned char *ring, int offset)
{
    return (uint32_t *)(void *)(ring + offset);
}

static int as_int(PyObject *object)
{
    long value = PyLong_AsLong(object);
    if (value == -1 && PyErr_Occurred()) {
        return -1;
    }
    if (value < INT_MIN || value > INT_MAX) {
        PyErr_SetString(PyExc_OverflowError, "an int of C's int size was expected");
        return -1;
    }
    return (int)value;
}

/* Checked indices: 0 and *used set, or -1 when they break the invariant. */
static int ring_published(unsigned char *ring, uint64_t capacity, uint64_t *tail, uint64_t *head, uint64_t *used)
{
    *head = __atomic_load_n(ring_u64(ring, RING_HEAD), __ATOMIC_ACQUIRE);
    *tail = __atomic_load_n(ring_u64(ring, RING_TAIL), __ATOMIC_ACQUIRE);
    *used = *tail - *head; /* unsigned: a tail behind the head is a huge number */
    return *used > capacity ? -1 : 0;
}

/* Clear a set flag; 1 if this call cleared it (the caller rings), 0 if it was clear. */
static int ring_take(unsigned char *ring, int flag)
{
    uint32_t expected = 1;
    if (__atomic_load_n(ring_u32(ring, flag), __ATOMIC_RELAXED) == 0) {
        return 0;
    }
    return __atomic_compare_exchange_n(ring_u32(ring, flag), &expected, 0, 0, __ATOMIC_SEQ_CST, __ATOMIC_RELAXED);
}

/* Copy up to `size` bytes in and publish them: the bytes written, or -1 (broken indices). With
 * `whole`, nothing unless all of them fit. */
static Py_ssize_t ring_put_bytes(unsigned char *ring, uint64_t capacity, const char *data, Py_ssize_t size, int whole)
{
    uint64_t tail, head, used;
    if (ring_published(ring, capacity, &tail, &head, &used) < 0) {
        return -1;
    }
    uint64_t room = capacity - used;
    if ((uint64_t)size > room) {
        if (whole) {
            return 0;
        }
        size = (Py_ssize_t)room;
    }
    if (size == 0) {
        return 0;
    }
    uint64_t at = tail & (capacity - 1);
    uint64_t first = capacity - at < (uint64_t)size ? capacity - at : (uint64_t)size;
    memcpy(ring + RING_HEADER + at, data, (size_t)first);
    if (first < (uint64_t)size) {
        memcpy(ring + RING_HEADER, data + first, (size_t)((uint64_t)size - first));
    }
    __atomic_store_n(ring_u64(ring, RING_TAIL), tail + (uint64_t)size, __ATOMIC_RELEASE);
    return size;
}

/* The ring's memory from a writable buffer: 0, or -1 with an exception set. */
static int ring_view(PyObject *object, Py_buffer *view, uint64_t *capacity)
{
    if (PyObject_GetBuffer(object, view, PyBUF_WRITABLE) != 0) {
        return -1;
    }
    uint64_t size = view->len > RING_HEADER ? (uint64_t)(view->len - RING_HEADER) : 0;
    if (size == 0 || (size & (size - 1)) != 0 || ((uintptr_t)view->buf & 63) != 0) {
        PyBuffer_Release(view);
        PyErr_SetString(PyExc_ValueError, "a ring is a 64-byte aligned header of 4096 bytes and a power of two");
        return -1;
    }
    *capacity = size;
    return 0;
}

static PyObject *ring_corrupt(void)
{
    PyErr_SetString(PyExc_ValueError, "the ring's indices are impossible: more than its capacity apart");
    return NULL;
}

/* ring_write(memory, data) -> int: ring.ring_write_python. */
static PyObject *ring_write(PyObject *module, PyObject *const *args, Py_ssize_t nargs)
{
    (void)module;
    if (nargs != 2) {
        PyErr_Format(PyExc_TypeError, "ring_write() takes 2 arguments (%zd given)", nargs);
        return NULL;
    }
    Py_buffer view, data;
    uint64_t capacity;
    if (ring_view(args[0], &view, &capacity) < 0) {
        return NULL;
    }
    if (PyObject_GetBuffer(args[1], &data, PyBUF_SIMPLE) != 0) {
        PyBuffer_Release(&view);
        return NULL;
    }
    Py_ssize_t written = ring_put_bytes(view.buf, capacity, data.buf, data.len, 0);
    PyBuffer_Release(&data);
    PyBuffer_Release(&view);
    return written < 0 ? ring_corrupt() : PyLong_FromSsize_t(written);
}

/* ring_read(memory, into, limit, room_fd) -> int: ring.ring_read_python. */
static PyObject *ring_read(PyObject *module, PyObject *const *args, Py_ssize_t nargs)
{
    (void)module;
    if (nargs != 4) {
        PyErr_Format(PyExc_TypeError, "ring_read() takes 4 arguments (%zd given)", nargs);
        return NULL;
    }
    if (!PyByteArray_Check(args[1])) {
        PyErr_SetString(PyExc_TypeError, "ring_read(): into must be a bytearray");
        return NULL;
    }
    Py_ssize_t limit = PyLong_AsSsize_t(args[2]);
    int room_fd = as_int(args[3]);
    if ((limit == -1 || room_fd == -1) && PyErr_Occurred()) {
        return NULL;
    }
    Py_buffer view;
    uint64_t capacity;
    if (ring_view(args[0], &view, &capacity) < 0) {
        return NULL;
    }
    unsigned char *ring = view.buf;
    uint64_t tail, head, used;
    if (ring_published(ring, capacity, &tail, &head, &used) < 0) {
        PyBuffer_Release(&view);
        return ring_corrupt();
    }
    uint64_t size = limit <= 0 ? 0 : used < (uint64_t)limit ? used : (uint64_t)limit;
    if (size == 0) {
        PyBuffer_Release(&view);
        return PyLong_FromLong(0);
    }
    PyObject *into = args[1];
    Py_ssize_t before = PyByteArray_GET_SIZE(into);
    if (PyByteArray_Resize(into, before + (Py_ssize_t)size) < 0) {
        PyBuffer_Release(&view);
        return NULL;
    }
    char *out = PyByteArray_AS_STRING(into) + before;
    uint64_t at = head & (capacity - 1);
    uint64_t first = capacity - at < size ? capacity - at : size;
    memcpy(out, ring + RING_HEADER + at, (size_t)first);
    if (first < size) {
        memcpy(out + first, ring + RING_HEADER, (size_t)(size - first));
    }
    /* The copy is done before the head says the room is free; then a full fence before the
     * sender's flag is read (Dekker: the sender sets it, fences, and reads the head). */
    __atomic_store_n(ring_u64(ring, RING_HEAD), head + size, __ATOMIC_RELEASE);
    __atomic_thread_fence(__ATOMIC_SEQ_CST);
    if (ring_take(ring, RING_WAITING)) {
        uint64_t one = 1;
        ssize_t rung = write(room_fd, &one, sizeof one);
        (void)rung; /* a full eventfd is rung already; a bad one is the sender's own loss */
    }
    PyBuffer_Release(&view);
    return PyLong_FromUnsignedLongLong(size);
}

/* ring_take_flag(memory, flag) -> bool: ring.take_flag_python, atomically. */
static PyObject *ring_take_flag(PyObject *module, PyObject *const *args, Py_ssize_t nargs)
{
    (void)module;
    if (nargs != 2) {
        PyErr_Format(PyExc_TypeError, "ring_take_flag() takes 2 arguments (%zd given)", nargs);
        return NULL;
    }
    int flag = as_int(args[1]);
    if (flag == -1 && PyErr_Occurred()) {
        return NULL;
    }
    if (flag != RING_SLEEPING && flag != RING_WAITING && flag != RING_CLOSED) {
        PyErr_SetString(PyExc_ValueError, "ring_take_flag(): not a flag's offset");
        return NULL;
    }
    Py_buffer view;
    uint64_t capacity;
    if (ring_view(args[0], &view, &capacity) < 0) {
        return NULL;
    }
    int taken = ring_take(view.buf, flag);
    PyBuffer_Release(&view);
    return PyBool_FromLong(taken);
}

/* SmallFrameWriter(fd, empty_frames, int_prefixes, fallback): PipeSender.put for the commonest
 * messages. Called with (label, payload): when the payload is None or an int of 8 bytes and the
 * codec has already built that label's frame (empty_frames) or prefix (int_prefixes), it writes
 * the frame (at most PIPE_BUF bytes: one write, never split nor interleaved) and returns None;
 * anything else, and any failed write, goes to fallback(item), the Python put, which builds
 * the frame, fills those caches and reports errors as it always does. */
typedef struct {
    PyObject_HEAD
    vectorcallfunc vectorcall;
    int fd;
    PyObject *empty_frames; /* label -> whole frame */
    PyObject *int_prefixes; /* label -> frame up to the int's 8 bytes */
    PyObject *fallback;
    /* The channel's one lock: every frame is written holding it, by this writer and by PipeSender
     * (which takes it as its own lock, through acquire/release), so that no frame, nor a failure
     * frame written from another thread, lands inside another that takes several writes. */
    PyThread_type_lock lock;
    int locked;
    /* Priority inheritance (anodize._session.inheriting): None, or a callable returning the context
     * in which a write that must wait for room lends the sender's priority. Set, every write first
     * tries without waiting (RWF_NOWAIT): the fast path makes no extra call. */
    PyObject *lend;
    /* Shared memory (ring.py): when has_ring, frames go into the ring and `fd` (the pipe's write
     * end, non-blocking) only carries a doorbell byte to a receiver that sleeps. */
    Py_buffer ring;
    int has_ring;
    uint64_t capacity;
} Writer;

/* Take the lock, waiting without the GIL if another thread holds it. */
static void take_lock(Writer *self)
{
    if (!PyThread_acquire_lock(self->lock, NOWAIT_LOCK)) {
        Py_BEGIN_ALLOW_THREADS
        PyThread_acquire_lock(self->lock, WAIT_LOCK);
        Py_END_ALLOW_THREADS
    }
    self->locked = 1;
}

static void give_lock(Writer *self)
{
    self->locked = 0;
    PyThread_release_lock(self->lock);
}

/* Write `size` bytes of `data` to fd as os.write in a loop would: the GIL released while each
 * write waits, and after an interrupted or short write the signal handlers run (one may
 * raise). *written counts the bytes that went. Returns 0 when all went, -1 with an exception
 * set when a handler raised, or the errno of the write that failed. */
static int write_out(int fd, const char *data, Py_ssize_t size, Py_ssize_t *written)
{
    *written = 0;
    while (*written < size) {
        ssize_t n;
        int failure;
        Py_BEGIN_ALLOW_THREADS
        n = write(fd, data + *written, (size_t)(size - *written));
        failure = n < 0 ? errno : 0;
        Py_END_ALLOW_THREADS
        if (failure != 0 && failure != EINTR) {
            return failure;
        }
        *written += n > 0 ? n : 0;
        if (*written < size && PyErr_CheckSignals() < 0) {
            return -1;
        }
    }
    return 0;
}

/* Call the context manager's __exit__(None, None, None), keeping any exception already set. */
static int exit_context(PyObject *context)
{
    PyObject *type, *value, *traceback;
    PyErr_Fetch(&type, &value, &traceback);
    PyObject *done = PyObject_CallMethod(context, "__exit__", "OOO", Py_None, Py_None, Py_None);
    int failed = done == NULL;
    Py_XDECREF(done);
    if (type != NULL) {
        if (failed) {
            PyErr_Clear();
        }
        PyErr_Restore(type, value, traceback);
        return -1;
    }
    return failed ? -1 : 0;
}

/* write_out, lending the sender's priority while it waits for room (self->lend set): one try
 * without waiting first; what did not fit is written inside the lend context. The bytes that
 * went are counted in *written even when the context fails (the frame is always completed). */
/* A frame into the ring, whole or not at all: 0 (published, the doorbell rung if the receiver
 * sleeps), EAGAIN (no room: nothing written; the Python path waits), EPIPE (the receiving end is
 * gone; *written says whether the frame went first), EBADMSG (the receiver broke the indices). */
static int ring_send(Writer *self, const char *data, Py_ssize_t size, Py_ssize_t *written)
{
    unsigned char *ring = self->ring.buf;
    *written = 0;
    if (__atomic_load_n(ring_u32(ring, RING_CLOSED), __ATOMIC_ACQUIRE) != 0) {
        return EPIPE;
    }
    Py_ssize_t put = ring_put_bytes(ring, self->capacity, data, size, 1);
    if (put < 0) {
        return EBADMSG;
    }
    if (put == 0) {
        return EAGAIN;
    }
    *written = size;
    /* Dekker with the receiver: tail published, full fence, then its flag (ring.py). */
    __atomic_thread_fence(__ATOMIC_SEQ_CST);
    if (ring_take(ring, RING_SLEEPING)) {
        char bell = 0;
        if (write(self->fd, &bell, 1) < 0 && errno == EPIPE) { /* a full pipe of bells wakes it too */
            __atomic_store_n(ring_u32(ring, RING_CLOSED), 1, __ATOMIC_RELEASE);
            return EPIPE;
        }
    }
    return 0;
}

static int write_lending(Writer *self, const char *data, Py_ssize_t size, Py_ssize_t *written)
{
    if (self->has_ring) {
        return ring_send(self, data, size, written);
    }
    if (self->lend == NULL || self->lend == Py_None) {
        return write_out(self->fd, data, size, written);
    }
    *written = 0;
    struct iovec iov = {(void *)data, (size_t)size};
    ssize_t n = pwritev2(self->fd, &iov, 1, -1, RWF_NOWAIT);
    if (n == size) {
        *written = size;
        return 0;
    }
    if (n < 0) {
        int failure = errno;
        if (failure == EOPNOTSUPP || failure == EINVAL || failure == ENOSYS) { /* no RWF_NOWAIT: plain */
            return write_out(self->fd, data, size, written);
        }
        if (failure != EAGAIN && failure != EINTR) {
            return failure;
        }
        n = 0;
    }
    PyObject *context = PyObject_CallNoArgs(self->lend);
    PyObject *entered = context ? PyObject_CallMethod(context, "__enter__", NULL) : NULL;
    Py_XDECREF(entered);
    Py_ssize_t rest = 0;
    int failure = write_out(self->fd, data + n, size - n, &rest); /* also when lending failed: whole frames only */
    *written = n + rest;
    if (context == NULL) {
        return -1;
    }
    if (entered == NULL) { /* an exception is set: report it after the frame went out */
        Py_DECREF(context);
        return -1;
    }
    int exited = exit_context(context);
    Py_DECREF(context);
    return failure != 0 ? failure : exited;
}

/* The frame of `item` into `frame` (PIPE_BUF bytes): its size, 0 if it is not a (label, payload)
 * tuple whose frame the codec has cached, -1 with an exception set. */
static Py_ssize_t small_frame(Writer *self, PyObject *item, char *frame)
{
    if (!PyTuple_CheckExact(item) || PyTuple_GET_SIZE(item) != 2) {
        return 0;
    }
    PyObject *label = PyTuple_GET_ITEM(item, 0), *payload = PyTuple_GET_ITEM(item, 1);
    Py_ssize_t size = 0;
    if (payload == Py_None) {
        PyObject *whole = PyDict_GetItemWithError(self->empty_frames, label);
        if (whole != NULL && PyBytes_CheckExact(whole) && PyBytes_GET_SIZE(whole) <= PIPE_BUF) {
            size = PyBytes_GET_SIZE(whole);
            memcpy(frame, PyBytes_AS_STRING(whole), (size_t)size);
        }
    } else if (PyLong_CheckExact(payload)) {
        int overflow = 0;
        long long value = PyLong_AsLongLongAndOverflow(payload, &overflow);
        PyObject *prefix = overflow == 0 && !(value == -1 && PyErr_Occurred())
            ? PyDict_GetItemWithError(self->int_prefixes, label) : NULL;
        if (prefix != NULL && PyBytes_CheckExact(prefix) && PyBytes_GET_SIZE(prefix) <= PIPE_BUF - 8) {
            size = PyBytes_GET_SIZE(prefix);
            memcpy(frame, PyBytes_AS_STRING(prefix), (size_t)size);
            unsigned long long bits = (unsigned long long)value;
            for (int i = 0; i < 8; i++) { /* little-endian, as struct's "<q" */
                frame[size++] = (char)(bits >> (8 * i));
            }
        }
    }
    return PyErr_Occurred() ? -1 : size;
}

#define BATCH_BYTES (64 * 1024) /* one write of a batch; the receiver reads as much at once */

/* The most bytes of the next batch: BATCH_BYTES, or less when the ring has less room (the room only
 * grows but for our own writes, made holding the lock: a batch sized so is written whole, and a
 * ring filling up does not send every frame to the Python path one by one). */
static Py_ssize_t batch_limit(Writer *self)
{
    if (!self->has_ring) {
        return BATCH_BYTES;
    }
    uint64_t tail, head, used;
    if (ring_published(self->ring.buf, self->capacity, &tail, &head, &used) < 0) {
        return BATCH_BYTES; /* the write reports the broken indices */
    }
    uint64_t room = self->capacity - used;
    return room < BATCH_BYTES ? (Py_ssize_t)room : BATCH_BYTES;
}

/* write_many(items, start) -> (taken, errno): the longest run of items from `start` whose frames
 * the codec has cached, written in writes of up to BATCH_BYTES; taken counts the items whose
 * frames are wholly in the pipe, errno is 0 or why the last write failed (the caller then
 * reports the peer gone and sends nothing more). PipeSender.put_many sends the rest. */
static PyObject *writer_write_many(Writer *self, PyObject *args)
{
    PyObject *items;
    Py_ssize_t start;
    if (!PyArg_ParseTuple(args, "O!n:write_many", &PyList_Type, &items, &start)) {
        return NULL;
    }
    if (start < 0) {
        PyErr_SetString(PyExc_ValueError, "write_many(): start must not be negative");
        return NULL;
    }
    /* The batch, and where each of its frames ends (a frame is at least 10 bytes: length, kind,
     * label size, tag), to count the frames a failed write left whole in the pipe. */
    enum { MOST_FRAMES = BATCH_BYTES / 10 };
    char *batch = PyMem_Malloc(BATCH_BYTES);
    Py_ssize_t *ends = PyMem_Malloc(MOST_FRAMES * sizeof(Py_ssize_t));
    if (batch == NULL || ends == NULL) {
        PyMem_Free(batch);
        PyMem_Free(ends);
        return PyErr_NoMemory();
    }
    Py_ssize_t taken = 0, in_batch = 0, size = 0;
    Py_ssize_t limit = batch_limit(self);
    int error = 0;
    for (Py_ssize_t index = start; !error; index++) {
        Py_ssize_t framed = 0;
        char frame[PIPE_BUF];
        if (index < PyList_GET_SIZE(items)) { /* re-read: the list may change while the GIL is released */
            PyObject *item = Py_NewRef(PyList_GET_ITEM(items, index));
            framed = small_frame(self, item, frame);
            Py_DECREF(item);
            if (framed < 0) {
                PyMem_Free(batch);
                PyMem_Free(ends);
                return NULL;
            }
        }
        if (in_batch > 0 && (framed == 0 || size + framed > limit || in_batch == MOST_FRAMES)) {
            Py_ssize_t written;
            take_lock(self);
            error = write_lending(self, batch, size, &written);
            give_lock(self);
            if (error < 0) { /* a signal handler raised */
                PyMem_Free(batch);
                PyMem_Free(ends);
                return NULL;
            }
            for (Py_ssize_t k = 0; k < in_batch && ends[k] <= written; k++) {
                taken++;
            }
            in_batch = size = 0;
            limit = batch_limit(self);
            if (error == EAGAIN && self->has_ring) { /* the ring is full: put_many waits in Python */
                error = 0;
                break;
            }
        }
        if (framed == 0 || error) {
            break;
        }
        memcpy(batch + size, frame, (size_t)framed);
        size += framed;
        ends[in_batch++] = size;
    }
    PyMem_Free(batch);
    PyMem_Free(ends);
    return Py_BuildValue("(ni)", taken, error);
}

/* acquire(blocking=True, timeout=-1) -> bool, as threading.Lock.acquire. */
static PyObject *writer_acquire(Writer *self, PyObject *args, PyObject *kwargs)
{
    int blocking = 1;
    double timeout = -1;
    static char *names[] = {"blocking", "timeout", NULL};
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "|pd:acquire", names, &blocking, &timeout)) {
        return NULL;
    }
    PY_TIMEOUT_T microseconds = !blocking ? 0 : timeout < 0 ? -1 : (PY_TIMEOUT_T)(timeout * 1e6);
    PyLockStatus status = PyThread_acquire_lock_timed(self->lock, 0, 0);
    if (status != PY_LOCK_ACQUIRED && microseconds != 0) {
        Py_BEGIN_ALLOW_THREADS
        status = PyThread_acquire_lock_timed(self->lock, microseconds, 0);
        Py_END_ALLOW_THREADS
    }
    if (status != PY_LOCK_ACQUIRED) {
        Py_RETURN_FALSE;
    }
    self->locked = 1;
    Py_RETURN_TRUE;
}

static PyObject *writer_release(Writer *self, PyObject *unused)
{
    (void)unused;
    if (!self->locked) {
        PyErr_SetString(PyExc_RuntimeError, "release unlocked lock");
        return NULL;
    }
    give_lock(self);
    Py_RETURN_NONE;
}

static PyObject *writer_enter(Writer *self, PyObject *unused)
{
    (void)unused;
    take_lock(self);
    Py_RETURN_TRUE;
}

static PyObject *writer_exit(Writer *self, PyObject *args)
{
    (void)args;
    return writer_release(self, NULL);
}

static PyMethodDef writer_methods[] = {
    {"acquire", (PyCFunction)(void (*)(void))writer_acquire, METH_VARARGS | METH_KEYWORDS,
     "acquire(blocking=True, timeout=-1) -> bool: the channel's lock, as threading.Lock's."},
    {"release", (PyCFunction)writer_release, METH_NOARGS, "release(): as threading.Lock's."},
    {"__enter__", (PyCFunction)writer_enter, METH_NOARGS, NULL},
    {"__exit__", (PyCFunction)writer_exit, METH_VARARGS, NULL},
    {"write_many", (PyCFunction)writer_write_many, METH_VARARGS,
     "write_many(items, start) -> (taken, errno): the items from start on whose frames are cached, "
     "written in few writes; see PipeSender.put_many."},
    {NULL, NULL, 0, NULL},
};

static PyObject *writer_call(Writer *self, PyObject *const *args, size_t nargsf, PyObject *kwnames)
{
    Py_ssize_t nargs = PyVectorcall_NARGS(nargsf);
    if (nargs != 1 || kwnames != NULL) {
        return PyObject_Vectorcall(self->fallback, args, nargsf, kwnames);
    }
    PyObject *item = args[0];
    char frame[PIPE_BUF];
    Py_ssize_t size = small_frame(self, item, frame);
    if (size < 0) {
        return NULL;
    }
    if (size > 0) {
        Py_ssize_t written;
        take_lock(self);
        int failed = write_lending(self, frame, size, &written);
        give_lock(self);
        if (failed < 0) {
            return NULL;
        }
        if (failed == 0) {
            Py_RETURN_NONE;
        }
        /* Nothing was written (a pipe takes PIPE_BUF bytes whole or not at all): the fallback
         * writes again and turns the error into the peer's failure. */
    }
    return PyObject_CallOneArg(self->fallback, item);
}

static PyObject *writer_new(PyTypeObject *type, PyObject *args, PyObject *kwargs)
{
    int fd;
    PyObject *empty_frames, *int_prefixes, *fallback, *ring = Py_None;
    static char *names[] = {"fd", "empty_frames", "int_prefixes", "fallback", "ring", NULL};
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "iO!O!O|O:SmallFrameWriter", names, &fd, &PyDict_Type,
                                     &empty_frames, &PyDict_Type, &int_prefixes, &fallback, &ring)) {
        return NULL;
    }
    if (!PyCallable_Check(fallback)) {
        PyErr_SetString(PyExc_TypeError, "SmallFrameWriter: fallback must be callable");
        return NULL;
    }
    Writer *self = (Writer *)type->tp_alloc(type, 0);
    if (self == NULL) {
        return NULL;
    }
    self->fd = fd;
    self->empty_frames = Py_NewRef(empty_frames);
    self->int_prefixes = Py_NewRef(int_prefixes);
    self->fallback = Py_NewRef(fallback);
    self->lend = Py_NewRef(Py_None);
    self->vectorcall = (vectorcallfunc)writer_call;
    self->lock = PyThread_allocate_lock();
    if (self->lock == NULL) {
        Py_DECREF(self);
        return PyErr_NoMemory();
    }
    if (ring != Py_None) {
        if (ring_view(ring, &self->ring, &self->capacity) < 0) {
            Py_DECREF(self);
            return NULL;
        }
        self->has_ring = 1;
    }
    return (PyObject *)self;
}

static int writer_traverse(Writer *self, visitproc visit, void *arg)
{
    Py_VISIT(Py_TYPE(self));
    Py_VISIT(self->empty_frames);
    Py_VISIT(self->int_prefixes);
    Py_VISIT(self->fallback);
    Py_VISIT(self->lend);
    return 0;
}

static int writer_clear(Writer *self)
{
    Py_CLEAR(self->empty_frames);
    Py_CLEAR(self->int_prefixes);
    Py_CLEAR(self->fallback); /* a bound method of the PipeSender that holds this writer: a cycle */
    Py_CLEAR(self->lend);
    return 0;
}

static void writer_dealloc(Writer *self)
{
    PyTypeObject *type = Py_TYPE(self);
    PyObject_GC_UnTrack(self);
    writer_clear(self);
    if (self->has_ring) {
        self->has_ring = 0;
        PyBuffer_Release(&self->ring);
    }
    if (self->lock != NULL) {
        if (self->locked) {
            PyThread_release_lock(self->lock);
        }
        PyThread_free_lock(self->lock);
    }
    type->tp_free((PyObject *)self);
    Py_DECREF(type);
}

static PyMemberDef writer_members[] = {
    {"__vectorcalloffset__", T_PYSSIZET, offsetof(Writer, vectorcall), READONLY, NULL},
    {"lend", T_OBJECT, offsetof(Writer, lend), 0,
     "None, or the context in which a write waiting for room lends the sender's priority."},
    {NULL, 0, 0, 0, NULL},
};

static PyType_Slot writer_slots[] = {
    {Py_tp_doc, "SmallFrameWriter(fd, empty_frames, int_prefixes, fallback): PipeSender.put, "
                "compiled for messages without a payload or with an 8-byte int."},
    {Py_tp_new, writer_new},
    {Py_tp_call, PyVectorcall_Call},
    {Py_tp_dealloc, writer_dealloc},
    {Py_tp_traverse, writer_traverse},
    {Py_tp_clear, writer_clear},
    {Py_tp_members, writer_members},
    {Py_tp_methods, writer_methods},
    {0, NULL},
};

static PyType_Spec writer_spec = {
    "anodize._transport._frames.SmallFrameWriter", sizeof(Writer), 0,
    Py_TPFLAGS_DEFAULT | Py_TPFLAGS_HAVE_GC | Py_TPFLAGS_HAVE_VECTORCALL, writer_slots,
};

static PyMethodDef methods[] = {
    {"decode_run", (PyCFunction)(void (*)(void))decode_run, METH_FASTCALL,
     "decode_run(buffer, at, names, into) -> int\n\nCodec.decode_run in C (see anodize._transport.codec)."},
    {"ring_write", (PyCFunction)(void (*)(void))ring_write, METH_FASTCALL,
     "ring_write(memory, data) -> int\n\nring.ring_write_python in C (see anodize._transport.ring)."},
    {"ring_read", (PyCFunction)(void (*)(void))ring_read, METH_FASTCALL,
     "ring_read(memory, into, limit, room_fd) -> int\n\nring.ring_read_python in C."},
    {"ring_take_flag", (PyCFunction)(void (*)(void))ring_take_flag, METH_FASTCALL,
     "ring_take_flag(memory, flag) -> bool\n\nring.take_flag_python, atomically."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef frames_module = {
    PyModuleDef_HEAD_INIT, "_frames",
    "The compiled hot path of anodize._transport.codec (a pure-Python fallback stays).", -1, methods,
    NULL, NULL, NULL, NULL,
};

PyMODINIT_FUNC PyInit__frames(void)
{
    PyObject *module = PyModule_Create(&frames_module);
    if (module == NULL) {
        return NULL;
    }
    PyObject *writer_type = PyType_FromSpec(&writer_spec);
    if (writer_type == NULL || PyModule_AddObject(module, "SmallFrameWriter", writer_type) < 0) {
        Py_XDECREF(writer_type);
        Py_DECREF(module);
        return NULL;
    }
    return module;
}
