/* The compiled hot path of anodize._session.endpoint: Endpoint.send and Endpoint.recv.
 *
 * EndpointCore is the base class of Endpoint when this module was built (endpoint.py falls
 * back to its pure-Python core otherwise, or when ANODIZE_PURE_PYTHON is set). It holds the
 * attributes the two calls read on every message, and does what the Python core does for
 * the commonest case only: a role without parallel branches, positional arguments, a message
 * its monitor allows at once (one look-up and an exact payload type), no failure or stop in
 * the network, and for recv no timeout and no doorbell. Anything else goes to the Python
 * core's send or recv (_send_python / _recv_python) before anything has happened, or, after
 * the monitor has stepped, to the same Python helpers the Python core calls at that point,
 * so both cores raise the same errors at the same moments. tests/anodize/session/test_endpoint_core.py
 * runs the endpoint tests on both.
 *
 * Code of the user's may run inside either call (a payload's methods in the full check, its
 * pickling in a channel's put or get, a stand-in monitor's attributes), and it may delete or
 * replace any attribute of the endpoint or of its monitor. So: every field a call uses is read
 * once when it starts and held by a strong reference until it ends (as the Python core reads
 * them into locals), nothing borrowed is used across a call that may run code, and a field
 * missing or not of the exact type expected sends the call to the Python core, which raises an
 * AnodizeError naming the role and the attribute (tests/anodize/session/test_hostile_payloads.py).
 * A payload's exact type is found by identity in the step's tuple of types, never hashed.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <structmember.h>

typedef struct {
    PyObject_HEAD
    PyObject *role;
    PyObject *plain;     /* True: no parallel composition (bool) */
    PyObject *monitor;   /* a Monitor, or None */
    PyObject *network;
    PyObject *out;       /* peer -> (channel, doorbell) */
    PyObject *in;        /* peer -> channel */
    PyObject *sent;      /* peer -> count */
    PyObject *received;  /* peer -> count */
    PyObject *waiting;   /* peer -> qsize, for channels that can tell */
    PyObject *high_water;
    PyObject *doorbell;  /* this role's doorbell, or None */
    PyObject *lending;   /* peer -> Lend: receives that lend their priority if they block (inheriting.py) */
    /* The monitor's tables (never changed after it is built), read from `cached` once. */
    PyObject *cached;
    PyObject *sends;
    PyObject *recvs;
    PyObject *recv_peers;
    Py_ssize_t state_offset; /* where the monitor's `state` slot lies in it, or -1: use getattr */
    /* The last step taken each way, with the state, peer and label objects it was looked up
     * for: a stream repeats them, and the tables never change, so it is taken again without a
     * look-up. Strong references, so the identities compared cannot be reused meanwhile. */
    Py_ssize_t send_state, recv_state;
    PyObject *send_peer, *send_label, *send_step;
    PyObject *recv_peer, *recv_label, *recv_step;
    /* Per state of the cached monitor, the step last taken there each way and the peer last found
     * in recv_peers there (Memo), so that a protocol whose loop has several states takes each
     * without a look-up either. Allocated with the tables' cache, cleared with it. */
    Py_ssize_t states;
    struct Memo *memos;
    /* The state object last looked up each way (0 send, 1 receive) and its memo: a loop that
     * stays in one state, or alternates a send state and a receive state, finds it by identity. */
    PyObject *memo_state[2];
    struct Memo *memo_found[2];
    Py_ssize_t lookups; /* table look-ups made (a memo missed): what the tests count, as _lookups */
} Core;

/* What a state remembers: the step taken on (peer, label), by identity, each way; the exact
 * types and target of that step (borrowed from it); a peer whose receive was allowed there.
 * Strong references to peer, label, step and allowed: an identity compared is never reused. */
typedef struct Memo {
    PyObject *send_peer, *send_label, *send_step;
    PyObject *recv_peer, *recv_label, *recv_step;
    PyObject *allowed;
} Memo;

static PyObject *empty_error; /* queue.Empty */
static PyObject *str_get_nowait;
static PyObject *str_state, *str_sends, *str_recvs, *str_recv_peers, *str_alarm, *str_put, *str_get,
    *str_send, *str_recv, *str_send_python, *str_recv_python, *str_refuse_if_down, *str_no_channel,
    *str_accept, *str_route, *kw_timeout;
static PyTypeObject *simple_queue_type; /* queue.SimpleQueue: the channels between threads */
static PyTypeObject *message_type; /* anodize._session.endpoint.Message, set by configure() */
static PyTypeObject *monitor_type, *rule_type; /* Monitor and timed.Rule, set by configure() */
static PyObject *str_clock, *str_previous, *str_earlier, *str_checked, *str_closest, *str_receives_from;
static PyObject *monotonic_ns; /* time.monotonic_ns: the clock of a live monitor */
static PyObject *one;

static void clear_memos(Core *self)
{
    Memo *memos = self->memos;
    Py_ssize_t states = self->states;
    self->memos = NULL; /* first: a decref below may run code that calls back into this core */
    self->states = 0;
    for (int way = 0; way < 2; way++) {
        self->memo_found[way] = NULL;
        Py_CLEAR(self->memo_state[way]);
    }
    for (Py_ssize_t i = 0; i < states; i++) {
        Py_XDECREF(memos[i].send_peer);
        Py_XDECREF(memos[i].send_label);
        Py_XDECREF(memos[i].send_step);
        Py_XDECREF(memos[i].recv_peer);
        Py_XDECREF(memos[i].recv_label);
        Py_XDECREF(memos[i].recv_step);
        Py_XDECREF(memos[i].allowed);
    }
    PyMem_Free(memos);
}

/* The memo of state `state` (an int object), or NULL: not an exact int in the range memoised.
 * `way`: which of the two last look-ups to try first and to replace (0 send, 1 receive). */
static Memo *memo_of(Core *self, PyObject *state, int way)
{
    if (state == self->memo_state[way] && state != NULL) {
        return self->memo_found[way];
    }
    if (state == NULL || !PyLong_CheckExact(state) || self->memos == NULL) {
        return NULL;
    }
    int overflow;
    long index = PyLong_AsLongAndOverflow(state, &overflow); /* an exact int: no code runs */
    if (overflow || index < 0 || index >= self->states) {
        if (index == -1 && PyErr_Occurred()) {
            PyErr_Clear();
        }
        return NULL;
    }
    Py_XSETREF(self->memo_state[way], Py_NewRef(state)); /* an int: its deallocation runs no code */
    self->memo_found[way] = &self->memos[index];
    return self->memo_found[way];
}

/* The state object in the monitor's slot, borrowed, when the slot is known (the cached monitor's). */
static PyObject *peek_state(Core *self, PyObject *monitor)
{
    if (self->state_offset < 0 || self->cached != monitor) {
        return NULL;
    }
    return *(PyObject **)((char *)monitor + self->state_offset);
}

/* The monitor's tables, cached for `monitor`; -1 with an exception set if they are not what they
 * should be. Getting them may run code (a stand-in monitor's attributes): the caller holds `monitor`. */
static int cache_tables_anew(Core *self, PyObject *monitor);

static inline int cache_tables(Core *self, PyObject *monitor)
{
    return self->cached == monitor ? 0 : cache_tables_anew(self, monitor);
}

static int cache_tables_anew(Core *self, PyObject *monitor)
{
    PyObject *sends = PyObject_GetAttr(monitor, str_sends);
    PyObject *recvs = sends ? PyObject_GetAttr(monitor, str_recvs) : NULL;
    PyObject *peers = recvs ? PyObject_GetAttr(monitor, str_recv_peers) : NULL;
    if (peers == NULL || !PyList_CheckExact(sends) || !PyList_CheckExact(recvs) || !PyList_CheckExact(peers)) {
        if (peers != NULL) {
            PyErr_SetString(PyExc_TypeError, "EndpointCore: the monitor's tables must be lists");
        }
        Py_XDECREF(sends);
        Py_XDECREF(recvs);
        Py_XDECREF(peers);
        return -1;
    }
    Py_XSETREF(self->sends, sends);
    Py_XSETREF(self->recvs, recvs);
    Py_XSETREF(self->recv_peers, peers);
    Py_XSETREF(self->cached, Py_NewRef(monitor));
    Py_CLEAR(self->send_peer);
    Py_CLEAR(self->send_label);
    Py_CLEAR(self->send_step);
    Py_CLEAR(self->recv_peer);
    Py_CLEAR(self->recv_label);
    Py_CLEAR(self->recv_step);
    clear_memos(self);
    Py_ssize_t states = PyList_GET_SIZE(self->sends);
    if (states > 0 && states <= (Py_ssize_t)(PY_SSIZE_T_MAX / sizeof(Memo))) {
        Memo *memos = PyMem_Calloc((size_t)states, sizeof(Memo));
        if (memos == NULL) {
            PyErr_NoMemory();
            return -1;
        }
        self->memos = memos;
        self->states = states;
    }
    /* Monitor declares __slots__: its `state` is then a member descriptor holding an object at
     * a fixed offset, read and written there as the descriptor itself does. */
    self->state_offset = -1;
    PyObject *descriptor = _PyType_Lookup(Py_TYPE(monitor), str_state); /* borrowed */
    if (descriptor != NULL && Py_IS_TYPE(descriptor, &PyMemberDescr_Type)
            && PyObject_TypeCheck(monitor, ((PyDescrObject *)descriptor)->d_type)) {
        PyMemberDef *member = ((PyMemberDescrObject *)descriptor)->d_member;
        if (member->type == T_OBJECT_EX && !(member->flags & READONLY)) {
            self->state_offset = member->offset;
        }
    }
    return 0;
}

/* The monitor's state object (a new reference), or NULL with an exception set. */
static PyObject *get_state(Core *self, PyObject *monitor)
{
    if (self->state_offset >= 0 && self->cached == monitor) { /* the offset is this monitor's */
        PyObject *state = *(PyObject **)((char *)monitor + self->state_offset);
        if (state != NULL) {
            return Py_NewRef(state);
        }
    }
    return PyObject_GetAttr(monitor, str_state); /* raises as Python would, if unset */
}

static int set_state(Core *self, PyObject *monitor, PyObject *state)
{
    if (self->state_offset < 0 || self->cached != monitor) {
        return PyObject_SetAttr(monitor, str_state, state);
    }
    PyObject **slot = (PyObject **)((char *)monitor + self->state_offset);
    Py_XSETREF(*slot, Py_NewRef(state));
    return 0;
}

/* The monitor's state, checked to index `table` (held by the caller); -1 with an exception set otherwise. */
static Py_ssize_t current_state(Core *self, PyObject *monitor, PyObject *table)
{
    PyObject *state = get_state(self, monitor);
    if (state == NULL) {
        return -1;
    }
    Py_ssize_t index = PyLong_AsSsize_t(state);
    Py_DECREF(state);
    if (index == -1 && PyErr_Occurred()) {
        return -1;
    }
    if (index < 0 || index >= PyList_GET_SIZE(table)) {
        PyErr_Format(PyExc_IndexError, "EndpointCore: monitor state %zd out of range", index);
        return -1;
    }
    return index;
}

/* Whether `kind` is one of the step's exact types (a tuple): by identity, as the Python core's
 * `id(type(payload)) in step[1]` does. A set of types would call a metaclass's __hash__ and
 * __eq__, which may say anything and run any code. */
static int exact_type(PyObject *types, PyObject *kind)
{
    for (Py_ssize_t i = 0; i < PyTuple_GET_SIZE(types); i++) {
        if (PyTuple_GET_ITEM(types, i) == kind) {
            return 1;
        }
    }
    return 0;
}

/* Whether `payload` is a dict with exactly the record's fields, each value of one of its field's
 * exact types: `fields` is ((name, (type, ...)), ...). Every key must be an exact str first, so
 * that the look-ups compare strs only: no code of the payload's runs here. */
static int record_fits(PyObject *fields, PyObject *payload)
{
    if (!PyDict_CheckExact(payload) || !PyTuple_CheckExact(fields) || PyDict_GET_SIZE(payload) != PyTuple_GET_SIZE(fields)) {
        return 0;
    }
    Py_ssize_t position = 0;
    PyObject *key, *value;
    while (PyDict_Next(payload, &position, &key, &value)) {
        if (!PyUnicode_CheckExact(key)) {
            return 0;
        }
    }
    for (Py_ssize_t i = 0; i < PyTuple_GET_SIZE(fields); i++) {
        PyObject *field = PyTuple_GET_ITEM(fields, i);
        if (!PyTuple_CheckExact(field) || PyTuple_GET_SIZE(field) != 2 || !PyUnicode_CheckExact(PyTuple_GET_ITEM(field, 0))
                || !PyTuple_CheckExact(PyTuple_GET_ITEM(field, 1))) {
            return 0;
        }
        value = PyDict_GetItemWithError(payload, PyTuple_GET_ITEM(field, 0)); /* borrowed; strs only compared */
        if (value == NULL) {
            PyErr_Clear();
            return 0;
        }
        if (!exact_type(PyTuple_GET_ITEM(field, 1), (PyObject *)Py_TYPE(value))) {
            return 0;
        }
    }
    return 1;
}

/* A C long long from an exact int, or 0 with *ok cleared (anything else, or out of range). */
static long long as_nanos(PyObject *value, int *ok)
{
    if (!PyLong_CheckExact(value)) {
        *ok = 0;
        return 0;
    }
    int overflow = 0;
    long long nanos = PyLong_AsLongLongAndOverflow(value, &overflow);
    if (overflow || (nanos == -1 && PyErr_Occurred())) {
        PyErr_Clear();
        *ok = 0;
    }
    return nanos;
}

/* setattr on an object of one of anodize's own slotted classes (exact type: no code runs). */
static int set_field(PyObject *obj, PyObject *name, PyObject *value)
{
    if (value == NULL) {
        return -1;
    }
    int result = PyObject_SetAttr(obj, name, value);
    Py_DECREF(value);
    return result;
}

/* A step with constraints (`step`, held by the caller), checked here as Monitor._constrained
 * checks it, when its plan (step[7], monitor.CompiledRule) allows: the payload's exact type or
 * record, the clock read once where the rule is timed, a send's deadline, the refinement's fast
 * check. Anything not passed at once goes to Monitor.send / recv, with the clock's reading if
 * one was taken (so the clock is read once per action, as in the Python core), which decides
 * and raises; nothing is changed before that. 1 taken, 0 not taken (the caller calls the
 * monitor without a reading), -1 error. */
static int constrained_step(Core *self, PyObject *monitor, int sending, PyObject *peer, PyObject *label,
                            PyObject *payload, PyObject *step)
{
    PyObject *plan = PyTuple_GET_ITEM(step, 7);
    if (!PyTuple_CheckExact(plan) || PyTuple_GET_SIZE(plan) != 6 || monitor_type == NULL || rule_type == NULL
            || !Py_IS_TYPE(monitor, monitor_type) || self->cached != monitor || self->state_offset < 0
            || (PyTuple_GET_ITEM(plan, 5) != Py_None && !Py_IS_TYPE(PyTuple_GET_ITEM(plan, 5), rule_type))) {
        return 0;
    }
    PyObject *types = PyTuple_GET_ITEM(plan, 0), *fields = PyTuple_GET_ITEM(plan, 1),
        *fast = PyTuple_GET_ITEM(plan, 2), *within = PyTuple_GET_ITEM(plan, 3), *rule = PyTuple_GET_ITEM(plan, 5);
    int stamps = PyTuple_GET_ITEM(plan, 4) == Py_True;
    if (fields == Py_None ? !PyTuple_CheckExact(types) || !exact_type(types, (PyObject *)Py_TYPE(payload))
                          : !record_fits(fields, payload)) {
        return 0;
    }
    PyObject *state = peek_state(self, monitor);
    if (state == NULL) {
        return 0;
    }
    Py_INCREF(state); /* compared after the code below: the identity is not reused meanwhile */
    int ok = 1, timed = within != Py_None || stamps;
    long long now = 0, deadline = 0, elapsed = 0, previous = 0;
    PyObject *now_obj = NULL, *previous_obj = NULL;
    int result = -1;
    if (timed) {
        PyObject *clock = PyObject_GetAttr(monitor, str_clock);
        now_obj = clock ? PyObject_CallNoArgs(clock) : NULL; /* may run code: a replay's clock */
        Py_XDECREF(clock);
        if (now_obj == NULL) {
            goto done;
        }
        now = as_nanos(now_obj, &ok);
        previous_obj = PyObject_GetAttr(monitor, str_previous);
        if (previous_obj == NULL) {
            goto done;
        }
        previous = previous_obj == Py_None ? now : as_nanos(previous_obj, &ok);
        if (within != Py_None) {
            deadline = as_nanos(within, &ok);
            long long margin;
            if (__builtin_sub_overflow(now, previous, &elapsed) || __builtin_sub_overflow(deadline, elapsed, &margin)) {
                ok = 0; /* times beyond a C long long: Python's ints */
            } else if (sending && elapsed > deadline) {
                ok = 0; /* missed: the monitor raises */
            }
        }
    }
    if (ok && fast != Py_None) {
        PyObject *earlier = PyObject_GetAttr(monitor, str_earlier);
        PyObject *held = earlier ? PyObject_CallFunctionObjArgs(fast, payload, earlier, NULL) : NULL;
        Py_XDECREF(earlier);
        if (held == NULL) {
            PyErr_Clear(); /* the reference evaluates it again, and says why */
        }
        ok = held == Py_True;
        Py_XDECREF(held);
    }
    /* Code ran (a clock, a predicate's reads): the step stands only if the state it was found
     * for is still the monitor's. */
    if (!ok || self->cached != monitor || peek_state(self, monitor) != state) {
        if (now_obj == NULL) {
            result = 0;
        } else {
            PyObject *args[6] = {NULL, monitor, peer, label, payload, now_obj};
            PyObject *done = PyObject_VectorcallMethod(sending ? str_send : str_recv, args + 1,
                                                       5 | PY_VECTORCALL_ARGUMENTS_OFFSET, NULL);
            result = done == NULL ? -1 : 1;
            Py_XDECREF(done);
        }
        goto done;
    }
    if (rule == Py_None) { /* a record's fields, no constraint: Monitor.send's plain step */
        result = set_state(self, monitor, PyTuple_GET_ITEM(step, 0)) < 0 ? -1 : 1;
        goto done;
    }
    /* Taken: what Monitor._constrained changes, in its order. */
    PyObject *checked = PyObject_GetAttr(rule, str_checked);
    if (set_field(rule, str_checked, checked ? PyNumber_Add(checked, one) : NULL) < 0) {
        Py_XDECREF(checked);
        goto done;
    }
    Py_DECREF(checked);
    if (timed && within != Py_None) {
        long long margin = deadline - elapsed; /* a receive's: only if the message was there in time */
        if (sending || (previous_obj != Py_None && margin >= 0)) {
            PyObject *closest = PyObject_GetAttr(rule, str_closest);
            if (closest == NULL) {
                goto done;
            }
            int known = 1;
            long long so_far = closest == Py_None ? 0 : as_nanos(closest, &known);
            Py_DECREF(closest);
            if ((closest == Py_None || (known && margin < so_far))
                    && set_field(rule, str_closest, PyLong_FromLongLong(margin)) < 0) {
                goto done;
            }
        }
    }
    if (stamps && PyObject_SetAttr(monitor, str_previous, now_obj) < 0) {
        goto done;
    }
    result = set_state(self, monitor, PyTuple_GET_ITEM(step, 0)) < 0 ? -1 : 1;
done:
    Py_DECREF(state);
    Py_XDECREF(now_obj);
    Py_XDECREF(previous_obj);
    return result;
}

/* The step `monitor` takes on (peer, label) with `payload`, sending or receiving, taken at once
 * if allowed with an exact payload type: 1 taken, 0 not found or needs the full check, -1 error.
 * Every object used across a call that may run code is held here; the last step taken each way
 * is reused only while the tables cached are this monitor's. */
static int try_step(Core *self, PyObject *monitor, int sending, PyObject *peer, PyObject *label, PyObject *payload)
{
    if (!PyUnicode_CheckExact(peer) || !PyUnicode_CheckExact(label)) {
        return 0; /* a str subclass may run code as a key: the full check, in Python */
    }
    if (cache_tables(self, monitor) < 0) {
        return -1;
    }
    /* The step taken last in this state on the same (peer, label): no look-up and no reference
     * counted but the state's. Nothing here runs code: the state read is an exact int (so is
     * the one it replaces), the payload's type is compared by identity. */
    Memo *memo = memo_of(self, peek_state(self, monitor), !sending);
    if (memo != NULL) {
        PyObject *step = sending ? memo->send_step : memo->recv_step;
        if (step != NULL && peer == (sending ? memo->send_peer : memo->recv_peer)
                && label == (sending ? memo->send_label : memo->recv_label)) {
            if (exact_type(PyTuple_GET_ITEM(step, 4), (PyObject *)Py_TYPE(payload))) {
                PyObject **slot = (PyObject **)((char *)monitor + self->state_offset);
                Py_SETREF(*slot, Py_NewRef(PyTuple_GET_ITEM(step, 0)));
                return 1;
            }
            if (PyTuple_GET_SIZE(step) >= 8 && PyTuple_GET_ITEM(step, 7) != Py_None) {
                Py_INCREF(step); /* the constrained check runs code (the clock, the predicate) */
                int taken = constrained_step(self, monitor, sending, peer, label, payload, step);
                Py_DECREF(step);
                return taken;
            }
        }
    }
    PyObject *tables = Py_NewRef(sending ? self->sends : self->recvs);
    Py_ssize_t state = current_state(self, monitor, tables); /* may run code: a stand-in's `state` */
    if (state < 0) {
        Py_DECREF(tables);
        return -1;
    }
    Py_ssize_t *last_state = sending ? &self->send_state : &self->recv_state;
    PyObject **last_peer = sending ? &self->send_peer : &self->recv_peer;
    PyObject **last_label = sending ? &self->send_label : &self->recv_label;
    PyObject **last_step = sending ? &self->send_step : &self->recv_step;
    int reuse = self->cached == monitor && *last_step != NULL && state == *last_state && peer == *last_peer
        && label == *last_label && (sending ? self->sends : self->recvs) == tables;
    PyObject *step;
    if (reuse) {
        step = Py_NewRef(*last_step);
    } else {
        PyObject *table = Py_NewRef(PyList_GET_ITEM(tables, state)); /* nothing ran since the range check */
        if (!PyDict_CheckExact(table)) {
            Py_DECREF(table);
            Py_DECREF(tables);
            PyErr_SetString(PyExc_TypeError, "EndpointCore: a monitor table must be a dict");
            return -1;
        }
        self->lookups++;
        PyObject *key = PyTuple_Pack(2, peer, label);
        step = key ? PyDict_GetItemWithError(table, key) : NULL; /* borrowed */
        Py_XINCREF(step);
        Py_XDECREF(key);
        Py_DECREF(table);
        if (step == NULL) {
            Py_DECREF(tables);
            return PyErr_Occurred() ? -1 : 0;
        }
        if (!PyTuple_CheckExact(step) || PyTuple_GET_SIZE(step) < 5 || !PyTuple_CheckExact(PyTuple_GET_ITEM(step, 4))) {
            Py_DECREF(step);
            Py_DECREF(tables);
            return 0;
        }
        if (self->cached == monitor && (sending ? self->sends : self->recvs) == tables) {
            *last_state = state;
            Py_XSETREF(*last_peer, Py_NewRef(peer));
            Py_XSETREF(*last_label, Py_NewRef(label));
            Py_XSETREF(*last_step, Py_NewRef(step));
            if (self->memos != NULL && state < self->states) { /* the tables are those the memos were made for */
                Memo *here = &self->memos[state];
                PyObject **memo_peer = sending ? &here->send_peer : &here->recv_peer;
                PyObject **memo_label = sending ? &here->send_label : &here->recv_label;
                PyObject **memo_step = sending ? &here->send_step : &here->recv_step;
                Py_XSETREF(*memo_peer, Py_NewRef(peer)); /* exact strs and a tuple: no code runs */
                Py_XSETREF(*memo_label, Py_NewRef(label));
                Py_XSETREF(*memo_step, Py_NewRef(step));
            }
        }
    }
    Py_DECREF(tables);
    int exact = exact_type(PyTuple_GET_ITEM(step, 4), (PyObject *)Py_TYPE(payload));
    if (exact) {
        exact = set_state(self, monitor, PyTuple_GET_ITEM(step, 0)) < 0 ? -1 : 1;
    } else if (PyTuple_GET_SIZE(step) >= 8 && PyTuple_GET_ITEM(step, 7) != Py_None) {
        exact = constrained_step(self, monitor, sending, peer, label, payload, step);
    }
    Py_DECREF(step);
    return exact;
}

/* counts[peer] += 1, on an exact dict the caller holds (the Python core's `sent[to] += 1`). */
static int count_one(PyObject *counts, PyObject *peer)
{
    PyObject *count = PyDict_GetItemWithError(counts, peer);
    if (count == NULL) {
        if (!PyErr_Occurred()) {
            PyErr_SetObject(PyExc_KeyError, peer);
        }
        return -1;
    }
    Py_INCREF(count); /* its __iadd__ may run code and empty the dict */
    PyObject *more = PyNumber_InPlaceAdd(count, one);
    Py_DECREF(count);
    if (more == NULL) {
        return -1;
    }
    int result = PyDict_SetItem(counts, peer, more);
    Py_DECREF(more);
    return result;
}

/* Call self.<name>(*args, **kwargs) as given (the Python core's own path). */
static PyObject *pass_on(Core *self, PyObject *name, PyObject *const *args, size_t nargsf, PyObject *kwnames)
{
    PyObject *method = PyObject_GetAttr((PyObject *)self, name);
    if (method == NULL) {
        return NULL;
    }
    PyObject *result = PyObject_Vectorcall(method, args, nargsf, kwnames);
    Py_DECREF(method);
    return result;
}

/* obj.<name>(a[, b[, c]]): n arguments. The slot before obj is spare, so the call may borrow it. */
static PyObject *call_method(PyObject *obj, PyObject *name, PyObject *a, PyObject *b, PyObject *c, Py_ssize_t n)
{
    PyObject *args[5] = {NULL, obj, a, b, c};
    return PyObject_VectorcallMethod(name, args + 1, (size_t)(n + 1) | PY_VECTORCALL_ARGUMENTS_OFFSET, NULL);
}

/* What send uses of the endpoint, read once when it starts and held (strong references) to the
 * end, as the Python core reads them into locals: code that runs meanwhile (a payload's methods,
 * a channel's put) may delete or replace the endpoint's attributes; that counts from the next call. */
typedef struct {
    PyObject *role, *monitor, *network, *out, *sent, *waiting, *high_water;
} SendFields;

/* The rest of send, on `f`, once the monitor has allowed it. */
static PyObject *send_out(Core *self, SendFields *f, PyObject *to, PyObject *label, PyObject *payload)
{
    PyObject *alarm = PyObject_GetAttr(f->network, str_alarm);
    if (alarm == NULL) {
        return NULL;
    }
    int raised = PyObject_IsTrue(alarm);
    Py_DECREF(alarm);
    if (raised < 0) {
        return NULL;
    }
    if (raised) {
        PyObject *done = call_method((PyObject *)self, str_refuse_if_down, to, label, NULL, 2);
        if (done == NULL) {
            return NULL;
        }
        Py_DECREF(done);
    }
    PyObject *route = PyDict_GetItemWithError(f->out, to); /* borrowed: (channel, doorbell) */
    if (route == NULL || route == Py_None) {
        return PyErr_Occurred() ? NULL : call_method((PyObject *)self, str_no_channel, to, NULL, NULL, 1);
    }
    Py_INCREF(route);
    if (!PyTuple_CheckExact(route) || PyTuple_GET_SIZE(route) != 2) { /* unpacked as Python unpacks it */
        PyObject *pair = call_method((PyObject *)self, str_route, route, NULL, NULL, 1);
        Py_SETREF(route, pair);
        if (route == NULL) {
            return NULL;
        }
    }
    PyObject *channel = Py_NewRef(PyTuple_GET_ITEM(route, 0)), *doorbell = Py_NewRef(PyTuple_GET_ITEM(route, 1));
    Py_DECREF(route);
    PyObject *item = PyTuple_Pack(2, label, payload);
    PyObject *put = item ? call_method(channel, str_put, item, NULL, NULL, 1) : NULL;
    Py_XDECREF(item);
    Py_DECREF(channel);
    if (put == NULL || count_one(f->sent, to) < 0) {
        Py_XDECREF(put);
        Py_DECREF(doorbell);
        return NULL;
    }
    Py_DECREF(put);
    PyObject *size_of = PyDict_GetItemWithError(f->waiting, to); /* borrowed */
    if (size_of != NULL) { /* the channel's high-water mark */
        Py_INCREF(size_of);
        PyObject *size = PyObject_CallNoArgs(size_of);
        Py_DECREF(size_of);
        PyObject *mark = size ? PyDict_GetItemWithError(f->high_water, to) : NULL;
        Py_XINCREF(mark); /* comparing may run code that empties the dict */
        int higher = mark ? PyObject_RichCompareBool(size, mark, Py_GT) : -1;
        Py_XDECREF(mark);
        if (higher > 0) {
            higher = PyDict_SetItem(f->high_water, to, size);
        }
        Py_XDECREF(size);
        if (higher < 0) {
            if (!PyErr_Occurred()) {
                PyErr_SetObject(PyExc_KeyError, to);
            }
            Py_DECREF(doorbell);
            return NULL;
        }
    } else if (PyErr_Occurred()) {
        Py_DECREF(doorbell);
        return NULL;
    }
    if (doorbell != Py_None) {
        PyObject *rung = call_method(doorbell, str_put, f->role, NULL, NULL, 1);
        Py_DECREF(doorbell);
        if (rung == NULL) {
            return NULL;
        }
        Py_DECREF(rung);
    } else {
        Py_DECREF(doorbell);
    }
    Py_RETURN_NONE;
}

static PyObject *core_send(Core *self, PyObject *const *args, Py_ssize_t nargsf, PyObject *kwnames)
{
    Py_ssize_t nargs = PyVectorcall_NARGS(nargsf);
    /* Role names of exact type str, and the endpoint's tables exact dicts: no code of theirs runs
     * in the look-ups below. Anything missing or else is the Python core's to raise or to do. */
    if (kwnames != NULL || nargs < 2 || nargs > 3 || !PyUnicode_CheckExact(args[0]) || self->plain != Py_True
            || self->role == NULL || self->monitor == NULL || self->network == NULL
            || self->out == NULL || !PyDict_CheckExact(self->out) || self->sent == NULL || !PyDict_CheckExact(self->sent)
            || self->waiting == NULL || !PyDict_CheckExact(self->waiting)
            || self->high_water == NULL || !PyDict_CheckExact(self->high_water)) {
        return pass_on(self, str_send_python, args, (size_t)nargsf, kwnames);
    }
    PyObject *to = args[0], *label = args[1], *payload = nargs == 3 ? args[2] : Py_None;
    SendFields f = {Py_NewRef(self->role), Py_NewRef(self->monitor), Py_NewRef(self->network), Py_NewRef(self->out),
                    Py_NewRef(self->sent), Py_NewRef(self->waiting), Py_NewRef(self->high_water)};
    PyObject *result = NULL;
    if (f.monitor != Py_None) { /* first: a forbidden send is a violation */
        int stepped = try_step(self, f.monitor, 1, to, label, payload);
        if (stepped == 0) { /* the full check, which raises or steps */
            PyObject *done = call_method(f.monitor, str_send, to, label, payload, 3);
            stepped = done == NULL ? -1 : 1;
            Py_XDECREF(done);
        }
        if (stepped < 0) {
            goto done;
        }
    }
    result = send_out(self, &f, to, label, payload);
done:
    Py_DECREF(f.role);
    Py_DECREF(f.monitor);
    Py_DECREF(f.network);
    Py_DECREF(f.out);
    Py_DECREF(f.sent);
    Py_DECREF(f.waiting);
    Py_DECREF(f.high_water);
    return result;
}

static PyObject *as_message(PyObject *item)
{
    PyObject *message = message_type->tp_alloc(message_type, 2);
    if (message == NULL) {
        return NULL;
    }
    PyTuple_SET_ITEM(message, 0, Py_NewRef(PyTuple_GET_ITEM(item, 0)));
    PyTuple_SET_ITEM(message, 1, Py_NewRef(PyTuple_GET_ITEM(item, 1)));
    return message;
}

/* Whether the monitor's state may receive from `frm` now without a timer (its recv_peers):
 * 1 yes, 0 no, -1 error. A yes is remembered for the state, by frm's identity (an exact str:
 * the caller checked), when the state is an exact int the memos cover. */
static int may_receive(Core *self, PyObject *monitor, PyObject *frm)
{
    self->lookups++;
    PyObject *table = Py_NewRef(self->recv_peers); /* what reading the state may run cannot free it */
    Py_ssize_t state = current_state(self, monitor, table);
    PyObject *peers = state < 0 ? NULL : Py_NewRef(PyList_GET_ITEM(table, state)); /* nor frm's __eq__ */
    int same = self->cached == monitor && self->recv_peers == table;
    Py_DECREF(table);
    if (peers == NULL) {
        return -1;
    }
    int allowed = PySequence_Contains(peers, frm);
    if (allowed > 0 && same && PyFrozenSet_CheckExact(peers)) { /* no code of a frozenset's ran */
        Memo *memo = memo_of(self, peek_state(self, monitor), 1);
        if (memo != NULL && memo == &self->memos[state]) {
            Py_XSETREF(memo->allowed, Py_NewRef(frm));
        }
    }
    Py_DECREF(peers);
    return allowed;
}

/* Whether a receive from `frm` may take a message already there in the monitor's state, where
 * the state's deadline keeps it off recv_peers: 1 yes (frm is one of the state's peers and the
 * monitor reads the machine's own clock, time.monotonic_ns: no replay, whose readings must come
 * in the Python core's order), 0 no, -1 error. Nothing waits in C under a deadline: the Python
 * core waits when nothing is there, having changed nothing. */
static int waits_under_deadline(Core *self, PyObject *monitor, PyObject *frm)
{
    if (monotonic_ns == NULL || monitor_type == NULL || !Py_IS_TYPE(monitor, monitor_type) || self->cached != monitor) {
        return 0;
    }
    PyObject *clock = PyObject_GetAttr(monitor, str_clock); /* exact Monitor: a slot, no code */
    if (clock == NULL) {
        return -1;
    }
    int live = clock == monotonic_ns;
    Py_DECREF(clock);
    if (!live) {
        return 0;
    }
    PyObject *all = PyObject_GetAttr(monitor, str_receives_from);
    if (all == NULL) {
        return -1;
    }
    int allowed = 0;
    if (PyList_CheckExact(all)) {
        Py_ssize_t state = current_state(self, monitor, all);
        if (state < 0) {
            Py_DECREF(all);
            return -1;
        }
        PyObject *peers = PyList_GET_ITEM(all, state);
        allowed = PyFrozenSet_CheckExact(peers) ? PySequence_Contains(peers, frm) : 0; /* an exact str */
    }
    Py_DECREF(all);
    return allowed;
}

/* What recv uses of the endpoint, read once when it starts and held to the end (see SendFields). */
typedef struct {
    PyObject *monitor, *in, *received, *lending;
} RecvFields;

/* recv on `f`: NULL with an exception set, or the message. */
static PyObject *recv_on(Core *self, RecvFields *f, PyObject *const *args, Py_ssize_t nargsf, PyObject *kwnames)
{
    PyObject *frm = args[0];
    int monitored = f->monitor != Py_None;
    int waiting = 1; /* 0: take only a message already there; else the Python core waits */
    if (monitored) {
        if (cache_tables(self, f->monitor) < 0) {
            return NULL;
        }
        Memo *memo = memo_of(self, peek_state(self, f->monitor), 1);
        int allowed = memo != NULL && memo->allowed == frm ? 1 : may_receive(self, f->monitor, frm);
        if (allowed == 0) { /* a deadline may run here: a message already there is taken (below) */
            allowed = waits_under_deadline(self, f->monitor, frm);
            waiting = allowed > 0 ? 0 : 1;
        }
        if (allowed <= 0) { /* not now: the Python core raises the violation, or waits to the deadline */
            return allowed < 0 ? NULL : pass_on(self, str_recv_python, args, (size_t)nargsf, kwnames);
        }
    }
    PyObject *channel = PyDict_GetItemWithError(f->in, frm); /* borrowed */
    if (channel == NULL || channel == Py_None) { /* the Python core's `if channel is None` */
        return PyErr_Occurred() ? NULL : pass_on(self, str_recv_python, args, (size_t)nargsf, kwnames);
    }
    Py_INCREF(channel);
    PyObject *item;
    PyObject *lend = PyDict_GET_SIZE(f->lending) > 0 ? PyDict_GetItemWithError(f->lending, frm) : NULL;
    if (lend == NULL && PyErr_Occurred()) {
        item = NULL;
    } else if (lend != NULL || !waiting) {
        /* Priority inheritance, or a deadline: a message already there is taken without a
         * scheduling call; if none is, the Python core lends while it waits, or waits no longer
         * than the deadline (nothing has happened yet: it checks again). */
        item = PyObject_CallMethodNoArgs(channel, str_get_nowait);
        if (item == NULL && PyErr_ExceptionMatches(empty_error)) {
            PyErr_Clear();
            Py_DECREF(channel);
            return pass_on(self, str_recv_python, args, (size_t)nargsf, kwnames);
        }
    } else if (Py_IS_TYPE(channel, simple_queue_type)) {
        /* A SimpleQueue's get() waits for ever by default: no keyword to parse (about 200
         * instructions a message). */
        item = PyObject_CallMethodNoArgs(channel, str_get);
    } else {
        PyObject *get_args[3] = {NULL, channel, Py_None}; /* channel.get(timeout=None), as the Python core calls it */
        item = PyObject_VectorcallMethod(str_get, get_args + 1, 1 | PY_VECTORCALL_ARGUMENTS_OFFSET, kw_timeout);
    }
    if (item == NULL) {
        Py_DECREF(channel);
        return NULL;
    }
    if (!PyTuple_CheckExact(item) || PyTuple_GET_SIZE(item) != 2) { /* a signal, or not a message */
        PyObject *accepted = call_method((PyObject *)self, str_accept, frm, item, channel, 3);
        Py_DECREF(item);
        Py_DECREF(channel);
        return accepted;
    }
    Py_DECREF(channel);
    /* Any code may have run in get() (unpickling a payload, say): the message is checked by the
     * monitor read before, as the Python core checks it; the tables are cached again if the
     * endpoint's monitor was replaced meanwhile. */
    PyObject *label = PyTuple_GET_ITEM(item, 0), *payload = PyTuple_GET_ITEM(item, 1); /* item holds them */
    if (monitored) {
        int stepped = try_step(self, f->monitor, 0, frm, label, payload);
        if (stepped == 0) { /* the full check, which raises (blaming the sender) or steps */
            PyObject *done = call_method(f->monitor, str_recv, frm, label, payload, 3);
            stepped = done == NULL ? -1 : 1;
            Py_XDECREF(done);
        }
        if (stepped < 0) {
            Py_DECREF(item);
            return NULL;
        }
    }
    if (count_one(f->received, frm) < 0) {
        Py_DECREF(item);
        return NULL;
    }
    PyObject *message = as_message(item);
    Py_DECREF(item);
    return message;
}

static PyObject *core_recv(Core *self, PyObject *const *args, Py_ssize_t nargsf, PyObject *kwnames)
{
    Py_ssize_t nargs = PyVectorcall_NARGS(nargsf);
    if (kwnames != NULL || nargs < 1 || nargs > 2 || (nargs == 2 && args[1] != Py_None) || message_type == NULL
            || !PyUnicode_CheckExact(args[0]) || self->plain != Py_True || self->doorbell != Py_None
            || self->role == NULL || self->monitor == NULL || self->in == NULL || !PyDict_CheckExact(self->in)
            || self->received == NULL || !PyDict_CheckExact(self->received)
            || self->lending == NULL || !PyDict_CheckExact(self->lending)) {
        return pass_on(self, str_recv_python, args, (size_t)nargsf, kwnames);
    }
    RecvFields f = {Py_NewRef(self->monitor), Py_NewRef(self->in), Py_NewRef(self->received),
                    Py_NewRef(self->lending)};
    PyObject *result = recv_on(self, &f, args, nargsf, kwnames);
    Py_DECREF(f.monitor);
    Py_DECREF(f.in);
    Py_DECREF(f.received);
    Py_DECREF(f.lending);
    return result;
}

/* Every object field of Core, once: what traverse visits and clear clears. */
#define CORE_OBJECTS(X) \
    X(role) X(plain) X(monitor) X(network) X(out) X(in) X(sent) X(received) X(waiting) \
    X(high_water) X(doorbell) X(lending) X(cached) X(sends) X(recvs) X(recv_peers) \
    X(send_peer) X(send_label) X(send_step) X(recv_peer) X(recv_label) X(recv_step)

static int core_traverse(Core *self, visitproc visit, void *arg)
{
    Py_VISIT(Py_TYPE(self));
#define VISIT_FIELD(field) Py_VISIT(self->field);
    CORE_OBJECTS(VISIT_FIELD)
#undef VISIT_FIELD
    for (Py_ssize_t i = 0; i < self->states; i++) {
        Py_VISIT(self->memos[i].send_step);
        Py_VISIT(self->memos[i].recv_step);
    }
    return 0;
}

static int core_clear(Core *self)
{
#define CLEAR_FIELD(field) Py_CLEAR(self->field);
    CORE_OBJECTS(CLEAR_FIELD)
#undef CLEAR_FIELD
    clear_memos(self);
    return 0;
}

static void core_dealloc(Core *self)
{
    PyTypeObject *type = Py_TYPE(self);
    PyObject_GC_UnTrack(self);
    core_clear(self);
    type->tp_free((PyObject *)self);
    Py_DECREF(type); /* a heap type's instances hold a reference to it */
}

static PyObject *core_new(PyTypeObject *type, PyObject *args, PyObject *kwargs)
{
    (void)args;
    (void)kwargs;
    Core *self = (Core *)type->tp_alloc(type, 0);
    if (self != NULL) {
        self->plain = Py_NewRef(Py_False);
        self->doorbell = Py_NewRef(Py_None);
        self->monitor = Py_NewRef(Py_None);
        self->state_offset = -1;
    }
    return (PyObject *)self;
}

#define MEMBER(name, field) {name, T_OBJECT_EX, offsetof(Core, field), 0, NULL}
static PyMemberDef core_members[] = {
    MEMBER("role", role), MEMBER("_plain", plain), MEMBER("_monitor", monitor),
    MEMBER("_network", network), MEMBER("_out", out), MEMBER("_in", in), MEMBER("sent", sent),
    MEMBER("received", received), MEMBER("_waiting", waiting), MEMBER("high_water", high_water),
    MEMBER("_doorbell", doorbell), MEMBER("_lending", lending),
    {"_lookups", T_PYSSIZET, offsetof(Core, lookups), READONLY, "table look-ups made so far (a memo missed)"},
    {NULL, 0, 0, 0, NULL},
};

static PyMethodDef core_methods[] = {
    {"send", (PyCFunction)(void (*)(void))core_send, METH_FASTCALL | METH_KEYWORDS,
     "send($self, to, label, payload=None)\n--\n\n"
     "Send label (with payload) to role to.\n\n"
     "Raises ProtocolViolationError if the local type does not allow it now (nothing is sent),\n"
     "PeerFailedError if to has failed. The compiled core; Endpoint._send_python is the reference."},
    {"recv", (PyCFunction)(void (*)(void))core_recv, METH_FASTCALL | METH_KEYWORDS,
     "recv($self, frm, timeout=None)\n--\n\n"
     "Receive the next message from role frm, as a Message (label, payload).\n\n"
     "Raises ProtocolViolationError if this role may not receive from frm now (blame: this role)\n"
     "or the message is not allowed (blame: frm), PeerFailedError if frm failed before sending,\n"
     "TimeoutError if nothing arrived within timeout seconds. The compiled core;\n"
     "Endpoint._recv_python is the reference."},
    {NULL, NULL, 0, NULL},
};

static PyType_Slot core_slots[] = {
    {Py_tp_doc, "The compiled core of Endpoint: its send and recv on the commonest path."},
    {Py_tp_new, core_new},
    {Py_tp_dealloc, core_dealloc},
    {Py_tp_traverse, core_traverse},
    {Py_tp_clear, core_clear},
    {Py_tp_members, core_members},
    {Py_tp_methods, core_methods},
    {0, NULL},
};

static PyType_Spec core_spec = {
    "anodize._session._endpoint_core.EndpointCore", sizeof(Core), 0,
    Py_TPFLAGS_DEFAULT | Py_TPFLAGS_BASETYPE | Py_TPFLAGS_HAVE_GC, core_slots,
};

/* configure(Message, Monitor=None, Rule=None): the tuple subclass recv returns; the monitor's
 * and its rules' classes, whose constrained steps the core then checks itself (exact types only). */
static PyObject *configure(PyObject *module, PyObject *const *args, Py_ssize_t nargs)
{
    (void)module;
    if (nargs < 1 || nargs > 3) {
        PyErr_SetString(PyExc_TypeError, "configure(Message, Monitor=None, Rule=None)");
        return NULL;
    }
    PyObject *type = args[0];
    if (!PyType_Check(type) || !PyType_IsSubtype((PyTypeObject *)type, &PyTuple_Type)) {
        PyErr_SetString(PyExc_TypeError, "configure(): the message type must be a tuple subclass");
        return NULL;
    }
    for (Py_ssize_t i = 1; i < nargs; i++) {
        if (!PyType_Check(args[i])) {
            PyErr_SetString(PyExc_TypeError, "configure(): Monitor and Rule must be classes");
            return NULL;
        }
    }
    Py_XSETREF(message_type, (PyTypeObject *)Py_NewRef(type));
    Py_XSETREF(monitor_type, nargs > 1 ? (PyTypeObject *)Py_NewRef(args[1]) : NULL);
    Py_XSETREF(rule_type, nargs > 2 ? (PyTypeObject *)Py_NewRef(args[2]) : NULL);
    Py_RETURN_NONE;
}

static PyMethodDef module_methods[] = {
    {"configure", (PyCFunction)(void (*)(void))configure, METH_FASTCALL,
     "configure(Message, Monitor=None, Rule=None): the tuple subclass that recv returns; the classes\n"
     "whose constrained steps the core checks itself."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef core_module = {
    PyModuleDef_HEAD_INIT, "_endpoint_core",
    "The compiled hot path of anodize._session.endpoint (a pure-Python core stays).", -1, module_methods,
    NULL, NULL, NULL, NULL,
};

#define INTERN(var, text) \
    if ((var = PyUnicode_InternFromString(text)) == NULL) return NULL

PyMODINIT_FUNC PyInit__endpoint_core(void)
{
    INTERN(str_state, "state");
    INTERN(str_clock, "clock");
    INTERN(str_previous, "previous");
    INTERN(str_earlier, "earlier");
    INTERN(str_checked, "checked");
    INTERN(str_closest, "closest");
    INTERN(str_receives_from, "receives_from");
    PyObject *time_module = PyImport_ImportModule("time");
    monotonic_ns = time_module ? PyObject_GetAttrString(time_module, "monotonic_ns") : NULL;
    Py_XDECREF(time_module);
    if (monotonic_ns == NULL) {
        return NULL;
    }
    INTERN(str_sends, "sends");
    INTERN(str_recvs, "recvs");
    INTERN(str_recv_peers, "recv_peers");
    INTERN(str_alarm, "alarm");
    INTERN(str_put, "put");
    INTERN(str_get, "get");
    INTERN(str_get_nowait, "get_nowait");
    PyObject *queue_module = PyImport_ImportModule("queue");
    empty_error = queue_module ? PyObject_GetAttrString(queue_module, "Empty") : NULL;
    simple_queue_type = queue_module ? (PyTypeObject *)PyObject_GetAttrString(queue_module, "SimpleQueue") : NULL;
    Py_XDECREF(queue_module);
    if (empty_error == NULL || simple_queue_type == NULL || !PyType_Check((PyObject *)simple_queue_type)) {
        return NULL;
    }
    INTERN(str_send, "send");
    INTERN(str_recv, "recv");
    INTERN(str_send_python, "_send_python");
    INTERN(str_recv_python, "_recv_python");
    INTERN(str_refuse_if_down, "_refuse_if_down");
    INTERN(str_no_channel, "_no_channel");
    INTERN(str_accept, "_accept");
    INTERN(str_route, "_route");
    if ((one = PyLong_FromLong(1)) == NULL || (kw_timeout = Py_BuildValue("(s)", "timeout")) == NULL) {
        return NULL;
    }
    PyObject *module = PyModule_Create(&core_module);
    if (module == NULL) {
        return NULL;
    }
    PyObject *core_type = PyType_FromSpec(&core_spec);
    if (core_type == NULL || PyModule_AddObject(module, "EndpointCore", core_type) < 0) {
        Py_XDECREF(core_type);
        Py_DECREF(module);
        return NULL;
    }
    return module;
}
