#!/usr/bin/env python3
"""Differential fuzzing of the declaration resolver: old (inlining) vs new (sharing).

Commit a1e7552 replaced "inline a fresh copy of a declaration's body at every
reference" (5a96d3e) with "resolve each body once per context and share the
node" (sessiontypes/expand.py, sessiontypes/sharing.py). The meaning must not
change. This tool generates many small ``.proto`` texts that stress the
resolver (declarations referring to each other in cycles, DAGs and
self-references; ``mu`` variables named like declarations, so that capture
and renaming happen; references inside parallel compositions; unguarded
cycles of references; undeclared names; ``local`` declarations in binary and
multiparty form; merges in roles not involved in a choice) and runs both
implementations on the same texts, each in its own subprocess, comparing:

* accepted or rejected; on rejection the sorted set of diagnostics
  (line, column, severity, message);
* on acceptance the warnings, ``print_global(module.globals[n].body)``, the
  roles, ``print_local(glob.project(role).body)`` for every role and
  ``print_local(module.locals[n].body)``.

Discrepancies are grouped by kind (which diagnostics only one side reports,
with names blotted out; which prints differ, and whether the two prints are
merely alpha-equivalent, i.e. differ only in the names of bound variables).
The first file of each kind is shrunk (declarations dropped, subtrees
replaced by ``end`` or by a child, branches dropped) while it still differs
in the same way, and the minimal files are printed with both outputs.

To tell which side of a discrepancy is wrong, ``--make-oracle DIR`` writes
the old package with its renaming of ``mu`` variables corrected (a renamed
``mu`` stays bound under its written name; the new name avoids every name in
scope and every name written in the ``mu``'s body); compare against it with
``--old DIR``.

Run it from the repository root::

    mkdir -p /tmp/oldimpl
    git archive 5a96d3e sessiontypes | tar -x -C /tmp/oldimpl
    .venv/bin/python scripts/fuzz_resolver_vs_old.py --cases 20000 --seed 1

    # against the corrected old resolver
    .venv/bin/python scripts/fuzz_resolver_vs_old.py --make-oracle /tmp/oracle
    .venv/bin/python scripts/fuzz_resolver_vs_old.py --old /tmp/oracle --cases 20000

About 150 files a second with two cores.

Options: ``--old ROOT`` (default /tmp/oldimpl: a directory holding the old
``sessiontypes`` package), ``--new ROOT`` (default: this checkout),
``--batch N`` texts per request to a worker, ``--timeout S`` seconds per text
(a text either side times out on is skipped and counted), ``--show N`` how
many distinct discrepancies to shrink and print, ``--json FILE`` to write the
minimal repros and both outputs as JSON. The exit status is 1 when a
discrepancy was found.

Internally the same file is the worker: ``fuzz_resolver_vs_old.py --worker
ROOT`` reads one JSON list of texts per line on stdin and answers one JSON list
of outcomes per line.
"""

from __future__ import annotations

import argparse
import json
import random
import re
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve()
REPO = HERE.parent.parent


# ---------------------------------------------------------------------------------------
# Worker: evaluate texts with one implementation.


def _worker(root: str, timeout: float) -> None:
    import signal

    sys.path.insert(0, root)
    sys.setrecursionlimit(20000)
    import sessiontypes
    from sessiontypes.errors import ProtocolError
    from sessiontypes.printer import print_global, print_local

    loaded = Path(sessiontypes.__file__).resolve()
    if not str(loaded).startswith(str(Path(root).resolve())):
        raise SystemExit(f"worker for {root} imported {loaded}")

    class TimedOutError(Exception):
        pass

    def on_alarm(signum: int, frame: object) -> None:
        raise TimedOutError

    signal.signal(signal.SIGALRM, on_alarm)

    def diags(items: Any) -> list[list[Any]]:
        return sorted({(d.location.line, d.location.column, d.severity, d.message) for d in items})

    def evaluate(text: str) -> dict[str, Any]:
        try:
            module = sessiontypes.loads(text)
        except ProtocolError as error:
            return {"status": "rejected", "diagnostics": diags(getattr(error, "diagnostics", ()))}
        result: dict[str, Any] = {"status": "accepted", "warnings": diags(module.warnings),
                                  "globals": {}, "locals": {}}
        for name, glob in module.globals.items():
            projections: dict[str, str] = {}
            for role in glob.roles:
                try:
                    projections[role] = print_local(glob.project(role).body)
                except ProtocolError as error:  # should not happen: the check projects every role
                    projections[role] = f"<{type(error).__name__}: {error}>"
            result["globals"][name] = {"body": print_global(glob.body), "roles": list(glob.roles),
                                       "projections": projections}
        for name, local in module.locals.items():
            result["locals"][name] = print_local(local.body)
        return result

    def guarded(text: str) -> dict[str, Any]:
        signal.setitimer(signal.ITIMER_REAL, timeout)
        try:
            return evaluate(text)
        except TimedOutError:
            return {"status": "timeout"}
        except BaseException as error:
            return {"status": "crash", "error": f"{type(error).__name__}: {error}"[:500]}
        finally:
            signal.setitimer(signal.ITIMER_REAL, 0)

    for line in sys.stdin:
        texts = json.loads(line)
        sys.stdout.write(json.dumps([guarded(t) for t in texts]) + "\n")
        sys.stdout.flush()


class Worker:
    """A persistent subprocess evaluating texts with the implementation under ``root``."""

    def __init__(self, root: str, timeout: float) -> None:
        self.proc = subprocess.Popen(
            [sys.executable, str(HERE), "--worker", root, "--timeout", str(timeout)],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, cwd="/")

    def send(self, texts: list[str]) -> None:
        assert self.proc.stdin is not None
        self.proc.stdin.write(json.dumps(texts) + "\n")
        self.proc.stdin.flush()

    def receive(self) -> list[dict[str, Any]]:
        assert self.proc.stdout is not None
        line = self.proc.stdout.readline()
        if not line:
            raise RuntimeError("worker died")
        return json.loads(line)

    def close(self) -> None:
        assert self.proc.stdin is not None
        self.proc.stdin.close()
        self.proc.wait()


class Pair:
    def __init__(self, old: str, new: str, timeout: float) -> None:
        self.old = Worker(old, timeout)
        self.new = Worker(new, timeout)

    def run(self, texts: list[str]) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
        self.old.send(texts)
        self.new.send(texts)  # both evaluate at once
        return self.old.receive(), self.new.receive()

    def close(self) -> None:
        self.old.close()
        self.new.close()


# ---------------------------------------------------------------------------------------
# Syntax trees and their text.
#
# global: ("end",) ("ref", n) ("msg", s, r, m, cont|None) ("choice", s, r, [(m, cont|None)])
#         ("mu", v, body) ("par", [g, ...])
# local:  ("end",) ("ref", n) ("send"|"recv", peer|None, m, cont|None)
#         ("sel"|"off", peer|None, [(m, cont|None)]) ("mu", v, body) ("par", [l, ...])
# message m: (label, None) bare, (label, "") label(), (label, sort) label(sort)
# file: [("global", name, roles|None, body) | ("local", name, role|None, body)
#        | ("type", name, target)]


def msg_text(m: tuple[str, str | None]) -> str:
    label, sort = m
    if sort is None:
        return label
    return f"{label}({sort})"


def g_text(t: tuple) -> str:
    kind = t[0]
    if kind == "end":
        return "end"
    if kind == "ref":
        return t[1]
    if kind == "msg":
        _, s, r, m, cont = t
        head = f"{s} -> {r} : {msg_text(m)}"
        return head if cont is None else f"{head}. {g_text(cont)}"
    if kind == "choice":
        _, s, r, branches = t
        parts = [msg_text(m) if c is None else f"{msg_text(m)}. {g_text(c)}" for m, c in branches]
        return f"{s} -> {r} : {{{', '.join(parts)}}}"
    if kind == "mu":
        return f"mu {t[1]}. {g_text(t[2])}"
    if kind == "par":
        return "(" + " || ".join(g_text(b) for b in t[1]) + ")"
    raise AssertionError(t)


def _l_cont(cont: tuple | None) -> str:
    if cont is None:
        return ""
    inner = l_text(cont)
    return f". {inner}"


def l_text(t: tuple) -> str:
    kind = t[0]
    if kind == "end":
        return "end"
    if kind == "ref":
        return t[1]
    if kind in ("send", "recv"):
        _, peer, m, cont = t
        arrow = "!" if kind == "send" else "?"
        if peer is None:
            return f"{arrow}{m[0]}{_l_cont(cont)}"
        return f"{arrow}{peer}({msg_text(m)}){_l_cont(cont)}"
    if kind in ("sel", "off"):
        _, peer, branches = t
        parts = [msg_text(m) if c is None else f"{msg_text(m)}. {l_text(c)}" for m, c in branches]
        return f"{'+' if kind == 'sel' else '&'}{peer or ''}{{{', '.join(parts)}}}"
    if kind == "mu":
        return f"mu {t[1]}. {l_text(t[2])}"
    if kind == "par":
        return "(" + " || ".join(l_text(b) for b in t[1]) + ")"
    raise AssertionError(t)


def file_text(decls: list[tuple]) -> str:
    lines = []
    for d in decls:
        if d[0] == "global":
            _, name, roles, body = d
            head = f"global {name}" + (f"({', '.join(roles)})" if roles is not None else "")
            lines.append(f"{head} = {g_text(body)}")
        elif d[0] == "local":
            _, name, role, body = d
            head = f"local {name}" + (f" at {role}" if role else "")
            lines.append(f"{head} = {l_text(body)}")
        else:
            lines.append(f'type {d[1]} = "{d[2]}"')
    return "\n".join(lines) + "\n"


# ---------------------------------------------------------------------------------------
# Generators.

ROLES = ["A", "B", "C", "D"]
GLOBAL_NAMES = ["G", "H", "K", "G'", "M", "A"]
LOCAL_NAMES = ["L", "L2", "P", "L'", "G"]
FRESH_VARS = ["t", "s", "t'", "u"]
LABELS = ["l", "r", "x", "y", "ok"]


class Gen:
    """A random small file: at most 5 declarations, type depth at most 4."""

    def __init__(self, rng: random.Random, clean: bool = False, cyclic: bool = False) -> None:
        self.rng = rng
        # cyclic: every global refers to the others (guarded, mostly), mu
        # variables named like declarations, other roles told of each choice:
        # many accepted files whose declarations form cycles.
        self.cyclic = cyclic
        self.inform = cyclic and rng.random() < 0.7
        clean = clean or cyclic
        # clean: fewer deliberate errors (undeclared names, self-sends, duplicate
        # labels, parallels, unguarded references), so more files are accepted
        # and their prints and projections get compared.
        self.clean = clean

    def choose(self, *weighted: tuple[float, Any]) -> Any:
        total = sum(w for w, _ in weighted)
        x = self.rng.random() * total
        for w, v in weighted:
            x -= w
            if x < 0:
                return v
        return weighted[-1][1]

    def message(self, sorts: list[str]) -> tuple[str, str | None]:
        r = self.rng.random()
        if r < 0.6:
            return (self.rng.choice(LABELS), None)
        if r < 0.7:
            return (self.rng.choice(LABELS), "")
        if r < 0.85:
            return (self.rng.choice(LABELS), self.rng.choice(sorts))
        return (self.rng.choice(sorts), None)  # bare sort name: label = sort

    def pair(self, roles: list[str]) -> tuple[str, str]:
        s = self.rng.choice(roles)
        if self.rng.random() < 0.02 and not self.clean:
            return s, s  # a role sending to itself
        r = self.rng.choice([x for x in roles if x != s])
        return s, r

    def mu_var(self, decls: list[str]) -> str:
        if self.rng.random() < (0.75 if self.cyclic else 0.6):
            return self.rng.choice(decls + [d + "'" for d in decls[:2]])
        return self.rng.choice(FRESH_VARS)

    def ref(self, decls: list[str], bound: list[str]) -> tuple:
        r = self.rng.random()
        if bound and r < 0.35:
            return ("ref", self.rng.choice(bound))
        if r < 0.93 or (self.clean and r < 0.995):
            return ("ref", self.rng.choice(decls))
        return ("ref", self.rng.choice(["Z", "L", "int", "T"]))  # undeclared, other kind, a sort

    def g(self, depth: int, decls: list[str], bound: list[str], roles: list[str],
          sorts: list[str]) -> tuple:
        if depth <= 0:
            return self.choose((0.25, ("end",)), (0.75, None)) or self.ref(decls, bound)
        if self.cyclic:
            kind = self.choose((0.40, "msg"), (0.30, "choice"), (0.15, "mu"), (0.01, "par"),
                               (0.04, "ref"), (0.02, "end"))
        elif self.clean:
            kind = self.choose((0.40, "msg"), (0.30, "choice"), (0.15, "mu"), (0.02, "par"),
                               (0.08, "ref"), (0.05, "end"))
        else:
            kind = self.choose((0.30, "msg"), (0.25, "choice"), (0.15, "mu"), (0.08, "par"),
                               (0.17, "ref"), (0.05, "end"))
        if kind == "end":
            return ("end",)
        if kind == "ref":
            return self.ref(decls, bound)
        if kind == "msg":
            s, r = self.pair(roles)
            cont = None if self.rng.random() < 0.1 else self.g(depth - 1, decls, bound, roles, sorts)
            return ("msg", s, r, self.message(sorts), cont)
        if kind == "choice":
            s, r = self.pair(roles)
            n = self.rng.choice([2, 2, 2, 3])
            labels = self.rng.sample(LABELS, n)
            if self.rng.random() < 0.03 and not self.clean:
                labels[-1] = labels[0]  # duplicate label
            branches = []
            for label in labels:
                m = (label, None) if self.rng.random() < 0.85 else (label, self.rng.choice(sorts))
                cont = None if self.rng.random() < 0.1 else self.g(depth - 1, decls, bound, roles, sorts)
                if self.inform:  # tell every other role which branch was taken: merges succeed
                    for other in roles:
                        if other not in (s, r):
                            cont = ("msg", s, other, (label, None), cont)
                branches.append((m, cont))
            return ("choice", s, r, branches)
        if kind == "mu":
            v = self.mu_var(decls)
            return ("mu", v, self.g(depth - 1, decls, [*bound, v], roles, sorts))
        # parallel: disjoint role pairs usually, so the channels differ
        n = 2
        if self.rng.random() < 0.7 and len(roles) >= 4:
            groups = [roles[:2], roles[2:4]]
        else:
            groups = [roles, roles]
        return ("par", [self.g(depth - 1, decls, bound, groups[i], sorts) for i in range(n)])

    def loc(self, depth: int, decls: list[str], bound: list[str], binary: bool,
          sorts: list[str]) -> tuple:
        if depth <= 0:
            return self.choose((0.25, ("end",)), (0.75, None)) or self.ref(decls, bound)
        if self.clean:
            kind = self.choose((0.45, "act"), (0.25, "choice"), (0.15, "mu"), (0.02, "par"),
                               (0.08, "ref"), (0.05, "end"))
        else:
            kind = self.choose((0.35, "act"), (0.2, "choice"), (0.15, "mu"), (0.07, "par"),
                               (0.18, "ref"), (0.05, "end"))
        if kind == "end":
            return ("end",)
        if kind == "ref":
            return self.ref(decls, bound)
        mixed = self.rng.random() < 0.05 and not self.clean
        peer = None if (binary != mixed) else self.rng.choice(["A", "B", "C"])
        if kind == "act":
            cont = None if self.rng.random() < 0.1 else self.loc(depth - 1, decls, bound, binary, sorts)
            m = (self.rng.choice(sorts + ([] if self.clean else ["x"])), None) if peer is None \
                else self.message(sorts)
            return (self.rng.choice(["send", "recv"]), peer, m, cont)
        if kind == "choice":
            labels = self.rng.sample(LABELS, self.rng.choice([2, 2, 3]))
            branches = [((lab, None), None if self.rng.random() < 0.1 else
                         self.loc(depth - 1, decls, bound, binary, sorts)) for lab in labels]
            return (self.rng.choice(["sel", "off"]), peer, branches)
        if kind == "mu":
            v = self.mu_var(decls)
            return ("mu", v, self.loc(depth - 1, decls, [*bound, v], binary, sorts))
        return ("par", [self.loc(depth - 1, decls, bound, binary, sorts) for _ in range(2)])

    def file(self) -> list[tuple]:
        rng = self.rng
        decls: list[tuple] = []
        sorts = ["int", "Int", "str"]
        if rng.random() < 0.2:
            decls.append(("type", "T", "m:T"))
            sorts = [*sorts, "T"]
        n_global = rng.choice([0, 1, 2, 2, 3, 3, 3, 4, 4, 5]) if rng.random() < 0.8 else 0
        n_local = rng.choice([0, 0, 1, 2, 3]) if n_global else rng.choice([1, 2, 3, 4])
        n_global = min(n_global, 5 - len(decls))
        n_local = min(n_local, 5 - len(decls) - n_global)
        gnames = rng.sample(GLOBAL_NAMES[:5], n_global) if n_global else []
        if gnames and rng.random() < 0.05:
            gnames[-1] = "A"  # a declaration named like a role
        lnames = rng.sample(LOCAL_NAMES[:4], n_local) if n_local else []
        if lnames and gnames and rng.random() < 0.05:
            lnames[-1] = gnames[0]  # same name, other kind: a duplicate
        nroles = rng.choice([2, 3] if self.cyclic else [2, 3, 3, 4])
        if self.cyclic:
            n_global = max(n_global, 2)
            n_local = min(n_local, 5 - len(decls) - n_global)
            gnames = rng.sample(GLOBAL_NAMES[:5], n_global)
            lnames = lnames[:max(n_local, 0)]
        roles = ROLES[:nroles]
        for name in gnames:
            depth = rng.choice([2, 3, 3, 4])
            body = self.g(depth, gnames, [], roles, sorts)
            role_list = None
            if rng.random() < 0.15 and not self.clean:
                role_list = list(roles) if rng.random() < 0.7 else rng.sample(roles, max(1, nroles - 1))
            decls.append(("global", name, role_list, body))
        binary = rng.random() < 0.5
        for name in lnames:
            depth = rng.choice([2, 3, 3, 4])
            body = self.loc(depth, lnames, [], binary, sorts)
            role = rng.choice([None, None, "A"])
            decls.append(("local", name, role, body))
        rng.shuffle(decls)
        return decls


def template(rng: random.Random) -> list[tuple]:
    """Hand-shaped corner cases, with random variation: capture, renaming, cycles, parallels."""
    gen = Gen(rng)
    which = rng.randrange(6)
    names = ["G", "H", "K"]
    roles = ["A", "B", "C"]

    def leaf() -> tuple:
        return gen.g(rng.choice([0, 1, 2]), names, [], roles, ["int"])

    if which == 0:  # global G = mu H. A -> B : {l. H, r. K}; H = ...; K = ... H ...
        v = rng.choice(["H", "G", "K", "G'"])
        return [("global", "G", None, ("mu", v, ("choice", "A", "B", [(("l", None), ("ref", v)),
                                                                     (("r", None), ("ref", "K"))]))),
                ("global", "H", None, ("msg", "B", "C", ("m", None), rng.choice([leaf(), ("ref", "G")]))),
                ("global", "K", None, ("msg", "C", "A", ("n", None), rng.choice([("ref", "H"), ("ref", "G"),
                                                                                  leaf()])))]
    if which == 1:  # a renamed mu whose body holds a mu named like the fresh name
        v = rng.choice(["G", "H"])
        inner = rng.choice([v + "'", v + "''", "t"])
        body = ("mu", v, ("choice", "A", "B", [
            (("l", None), ("mu", inner, ("choice", "B", "A", [(("x", None), ("ref", v)),
                                                            (("y", None), ("ref", inner))]))),
            (("r", None), ("ref", "K"))]))
        return [("global", "G", None, body if v == "G" else ("msg", "C", "A", ("go", None), body)),
                ("global", "H", None, ("msg", "A", "C", ("h", None), ("ref", "G"))),
                ("global", "K", None, ("msg", "C", "A", ("n", None), ("ref", v)))]
    if which == 2:  # unguarded cycles of references
        k = rng.choice([2, 3])
        decls = []
        for i in range(k):
            nxt = ("ref", names[(i + 1) % k])
            if rng.random() < 0.3:
                nxt = ("mu", rng.choice(["t", names[i]]), nxt)
            if rng.random() < 0.3:
                nxt = ("msg", "A", "B", ("m", None), nxt)
            decls.append(("global", names[i], None, nxt))
        return decls
    if which == 3:  # references inside a parallel composition
        return [("global", "G", None, ("msg", "A", "B", ("m", None),
                                       ("par", [("msg", "A", "B", ("x", None), rng.choice([("ref", "G"),
                                                                                        ("ref", "H")])),
                                                ("msg", "C", "D", ("y", None), rng.choice([("end",),
                                                                                          ("ref", "H")]))]))),
                ("global", "H", None, rng.choice([("msg", "C", "D", ("z", None), ("ref", "H")),
                                                  ("msg", "A", "B", ("z", None), ("ref", "G")),
                                                  ("mu", "t", ("msg", "A", "B", ("z", None), ("ref", "t")))]))]
    if which == 4:  # merges in a role not involved in the choice, through references
        return [("global", "G", None, ("choice", "A", "B", [
                    (("l", None), ("msg", "B", "C", (rng.choice(["x", "y"]), None), rng.choice([("ref", "H"),
                                                                                               ("ref", "G")]))),
                    (("r", None), ("msg", "B", "C", (rng.choice(["x", "y"]), None), rng.choice([("ref", "K"),
                                                                                               ("ref", "G"),
                                                                                               ("end",)])))])),
                ("global", "H", None, gen.g(2, names, [], roles, ["int"])),
                ("global", "K", None, gen.g(2, names, [], roles, ["int"]))]
    # locals referring to each other
    return [("local", "L", None, ("send", None, ("int", None), rng.choice([("ref", "L2"), ("ref", "L")]))),
            ("local", "L2", None, ("mu", rng.choice(["L", "t", "L2"]),
                                   ("recv", None, ("int", None), rng.choice([("ref", "L"), ("ref", "L2"),
                                                                             ("ref", "t")]))))]


def random_file(rng: random.Random) -> list[tuple]:
    if rng.random() < 0.15:
        return template(rng)
    r = rng.random()
    return Gen(rng, clean=r < 0.5, cyclic=r < 0.25).file()


# ---------------------------------------------------------------------------------------
# Comparison and shrinking.


def category(old: dict[str, Any], new: dict[str, Any]) -> str | None:
    """None when the outcomes agree, else a short name for how they differ."""
    if old == new:
        return None
    if "timeout" in (old["status"], new["status"]):
        return None  # not comparable
    if old["status"] != new["status"]:
        return f"status {old['status']} vs {new['status']}"
    if old["status"] == "crash":
        return "crash: " + old["error"].split(":")[0] + " vs " + new["error"].split(":")[0]
    if old["status"] == "rejected":
        return "diagnostics: " + _diagnostics_shape(old["diagnostics"], new["diagnostics"])
    parts = []
    if old["warnings"] != new["warnings"]:
        parts.append("warnings")
    og, ng = old["globals"], new["globals"]
    if list(og) != list(ng) or list(old["locals"]) != list(new["locals"]):
        parts.append("declarations")
    if any(og[n]["roles"] != ng[n]["roles"] for n in og if n in ng):
        parts.append("roles")
    # prints: alpha-equivalent (bound variables named differently) or not
    pairs = [("local", old["locals"][n], new["locals"][n], "locals")
             for n in old["locals"] if n in new["locals"]]
    for n in og:
        if n in ng:
            pairs.append(("global", og[n]["body"], ng[n]["body"], "global print"))
            for role, text in og[n]["projections"].items():
                pairs.append(("local", text, ng[n]["projections"].get(role, ""), "projection"))
    for kind, a, b, what in pairs:
        if a == b:
            continue
        if alpha_normal(kind, a) == alpha_normal(kind, b):
            what += " (alpha-equivalent)"
        if what not in parts:
            parts.append(what)
    return ", ".join(parts) or "other"


def alpha_normal(kind: str, text: str) -> object:
    """A print with its mu variables replaced by binding depth (de Bruijn levels); None if it does not parse."""
    if str(REPO) not in sys.path:
        sys.path.insert(0, str(REPO))
    from sessiontypes import syntax as s
    from sessiontypes.errors import ProtocolError
    from sessiontypes.parse import parse_file

    try:
        (decl,) = parse_file(f"{kind} X_ = {text}", "<print>").declarations
    except (ProtocolError, ValueError):
        return None

    def msg(m: s.MessageSyntax) -> object:
        return (m.label.text, m.sort.text if m.sort else None, m.parens)

    def walk(node: object, env: dict[str, int], depth: int) -> object:
        match node:
            case None | s.GEnd() | s.LEnd():
                return "end"
            case s.GRef(name=name) | s.LRef(name=name):
                return ("var", depth - 1 - env[name.text]) if name.text in env else ("free", name.text)
            case s.GRec(var=var, body=body) | s.LRec(var=var, body=body):
                return ("mu", walk(body, {**env, var.text: depth}, depth + 1))
            case s.GParallel(branches=parts) | s.LParallel(branches=parts):
                return ("par", tuple(walk(p, env, depth) for p in parts))
            case s.GInteraction(sender=a, receiver=b, branches=branches):
                return ("g", a.text, b.text,
                        tuple((msg(x.message), walk(x.continuation, env, depth)) for x in branches))
            case s.LAction(direction=d, peer=peer, message=m, continuation=c):
                return (d, peer.text if peer else None, msg(m), walk(c, env, depth))
            case s.LChoice(kind=k, peer=peer, branches=branches):
                return (k, peer.text if peer else None,
                        tuple((msg(x.message), walk(x.continuation, env, depth)) for x in branches))
        raise AssertionError(node)

    return walk(decl.body, {}, 0)


def _diagnostics_shape(old: list[list[Any]], new: list[list[Any]]) -> str:
    """The kinds of message only one side reports (names and numbers blotted out)."""
    a = {tuple(d) for d in old}
    b = {tuple(d) for d in new}

    def shape(d: tuple[Any, ...]) -> str:
        return re.sub(r"'[^']*'|\b[A-Z]\w*'*|\d+", "_", d[3])[:48]

    only_old = sorted({shape(d) for d in a - b})
    only_new = sorted({shape(d) for d in b - a})
    return f"old only {only_old}, new only {only_new}"


def _tree_variants(t: tuple | None, local: bool) -> list[tuple | None]:
    """Smaller trees than ``t``: each subtree replaced by end or by one of its children."""
    if t is None or t[0] in ("end",):
        return []
    out: list[tuple | None] = [("end",)]
    kind = t[0]
    if kind == "ref":
        return out
    if kind in ("msg", "send", "recv"):
        cont = t[-1]
        if cont is not None:
            out.append(cont)
            out.append((*t[:-1], None))
        out.extend((*t[:-1], v) for v in _tree_variants(cont, local))
        return out
    if kind in ("choice", "sel", "off"):
        branches = t[-1]
        for _, c in branches:
            if c is not None:
                out.append(c)
        if len(branches) > 1:
            out.extend((*t[:-1], branches[:i] + branches[i + 1:]) for i in range(len(branches)))
        for i, (m, c) in enumerate(branches):
            out.extend((*t[:-1], [*branches[:i], (m, v), *branches[i + 1:]])
                       for v in _tree_variants(c, local))
        return out
    if kind == "mu":
        out.append(t[2])
        out.extend(("mu", t[1], v) for v in _tree_variants(t[2], local))
        return out
    if kind == "par":
        parts = t[1]
        out.extend(parts)
        if len(parts) > 2:
            out.extend(("par", parts[:i] + parts[i + 1:]) for i in range(len(parts)))
        for i, p in enumerate(parts):
            out.extend(("par", [*parts[:i], v, *parts[i + 1:]]) for v in _tree_variants(p, local))
        return out
    return out


def file_variants(decls: list[tuple]) -> list[list[tuple]]:
    out = [decls[:i] + decls[i + 1:] for i in range(len(decls))]
    for i, d in enumerate(decls):
        if d[0] == "type":
            continue
        if d[0] == "global" and d[2] is not None:
            out.append([*decls[:i], ("global", d[1], None, d[3]), *decls[i + 1:]])
        if d[0] == "local" and d[2] is not None:
            out.append([*decls[:i], ("local", d[1], None, d[3]), *decls[i + 1:]])
        out.extend([*decls[:i], (*d[:3], v), *decls[i + 1:]] for v in _tree_variants(d[3], d[0] == "local"))
    return out


def shrink(pair: Pair, decls: list[tuple], cat: str, budget: int = 4000) -> list[tuple]:
    """Greedy: take the first smaller file that still differs the same way, until none does."""
    tried = 0
    while tried < budget:
        variants = file_variants(decls)
        variants.sort(key=lambda d: len(file_text(d)))
        found = None
        for start in range(0, len(variants), 64):
            chunk = variants[start:start + 64]
            texts = [file_text(v) for v in chunk]
            olds, news = pair.run(texts)
            tried += len(chunk)
            for v, o, n in zip(chunk, olds, news, strict=True):
                if category(o, n) == cat and len(file_text(v)) < len(file_text(decls)):
                    found = v
                    break
            if found is not None:
                break
        if found is None:
            return decls
        decls = found
    return decls


# ---------------------------------------------------------------------------------------
# An oracle: the old resolver with its renaming of mu variables corrected, to tell
# which side of a discrepancy is wrong (--make-oracle DIR, then --old DIR).

_ORACLE_PATCHES = [
    # A renamed mu stays bound under its written name (its body's uses of that
    # name are the mu, not the enclosing declaration) and stands for the new name.
    ("    name: str\n    depth: int", "    name: str\n    var: str\n    depth: int"),
    ("    def bind(self, name: str, depth: int, parallel_depth: int, declaration: bool) -> _Binder:",
     ("    def bind(self, name: str, depth: int, parallel_depth: int, declaration: bool,\n"
     "             var: str | None = None) -> _Binder:")),
    ("binder = _Binder(name, depth, parallel_depth, declaration, self.level, self.top.get(name))",
     ("binder = _Binder(name, var or name, depth, parallel_depth, declaration, self.level, "
     "self.top.get(name))")),
    ("hidden, binder = True, binder.shadowed",
     "hidden, binder = hidden or binder.var == name.text, binder.shadowed"),
    ("binder = scope.bind(name, depth, parallel_depth, declaration=False)",
     "binder = scope.bind(var, depth, parallel_depth, declaration=False, var=name)"),
    ("if capture.name != name:", "if capture.name != var or name != var:"),
    ("return g.Var(name.text, name.location)", "return g.Var(found.var, name.location)"),
    ("return lt.Var(name.text, name.location)", "return lt.Var(found.var, name.location)"),
    # The new name is not one in scope (written or renamed), nor one written in
    # the mu's body, where an inner mu of that name would capture it.
    ("             parallel_depth: int, build: Callable[[str], Term]) -> Term:",
     "             parallel_depth: int, build: Callable[[str], Term], body_syntax: object = None) -> Term:"),
    ("            taken = set(scope.top) | set(walk.declarations)",
     ("            taken = (set(scope.top) | {b.var for b in scope.top.values()} | set(walk.declarations)\n"
     "                     | _written_names(body_syntax))")),
    ("g.Rec(name, _resolve_g(walk, body, scope, depth,\n" + " " * 64 + "parallel_depth), location))",
     "g.Rec(name, _resolve_g(walk, body, scope, depth,\n" + " " * 64 + "parallel_depth), location), body)"),
    ("lt.Rec(name, _resolve_l(walk, body, scope, depth,\n" + " " * 65 + "parallel_depth), location))",
     "lt.Rec(name, _resolve_l(walk, body, scope, depth,\n" + " " * 65 + "parallel_depth), location), body)"),
]

_ORACLE_APPENDIX = '''

def _written_names(node: object) -> set[str]:
    """Every mu variable and name written in ``node`` (oracle patch)."""
    import dataclasses
    found: set[str] = set()
    stack = [node]
    while stack:
        n = stack.pop()
        if isinstance(n, (s.GRec, s.LRec)):
            found.add(n.var.text)
        if isinstance(n, (s.GRef, s.LRef)):
            found.add(n.name.text)
        if isinstance(n, (tuple, list)):
            stack.extend(n)
        elif dataclasses.is_dataclass(n) and not isinstance(n, s.Name):
            stack.extend(getattr(n, f.name) for f in dataclasses.fields(n))
    return found
'''


def make_oracle(old_root: str, target: str) -> None:
    """Copy the old package to ``target`` and correct its mu renaming."""
    import shutil

    dest = Path(target) / "sessiontypes"
    if dest.exists():
        shutil.rmtree(dest)
    shutil.copytree(Path(old_root) / "sessiontypes", dest)
    resolve = dest / "resolve.py"
    text = resolve.read_text()
    for before, after in _ORACLE_PATCHES:
        if text.count(before) != 1:
            raise SystemExit(f"the old resolve.py does not look as expected near {before!r}")
        text = text.replace(before, after)
    resolve.write_text(text + _ORACLE_APPENDIX)


# ---------------------------------------------------------------------------------------


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--worker", help=argparse.SUPPRESS)
    parser.add_argument("--old", default="/tmp/oldimpl")
    parser.add_argument("--new", default=str(REPO))
    parser.add_argument("--cases", type=int, default=20000)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--batch", type=int, default=250)
    parser.add_argument("--timeout", type=float, default=10.0)
    parser.add_argument("--show", type=int, default=20)
    parser.add_argument("--json", help="write the minimal repros here")
    parser.add_argument("--make-oracle", metavar="DIR",
                        help="write the old package with its mu renaming corrected to DIR, and stop")
    args = parser.parse_args()
    if args.worker:
        _worker(args.worker, args.timeout)
        return 0
    if args.make_oracle:
        make_oracle(args.old, args.make_oracle)
        return 0
    if not (Path(args.old) / "sessiontypes" / "resolve.py").exists():
        parser.error(f"no old sessiontypes under {args.old}; see the docstring")

    rng = random.Random(args.seed)
    pair = Pair(args.old, args.new, args.timeout)
    counts: dict[str, int] = {}
    statuses: dict[str, int] = {}
    first: dict[str, list[tuple]] = {}
    compared = skipped = 0
    seen_texts: set[str] = set()
    start = time.time()
    try:
        while compared + skipped < args.cases:
            batch: list[list[tuple]] = []
            while len(batch) < min(args.batch, args.cases - compared - skipped):
                decls = random_file(rng)
                text = file_text(decls)
                if text in seen_texts:
                    continue
                seen_texts.add(text)
                batch.append(decls)
            olds, news = pair.run([file_text(d) for d in batch])
            for decls, o, n in zip(batch, olds, news, strict=True):
                if "timeout" in (o["status"], n["status"]):
                    skipped += 1
                    continue
                compared += 1
                statuses[o["status"]] = statuses.get(o["status"], 0) + 1
                cat = category(o, n)
                if cat is not None:
                    counts[cat] = counts.get(cat, 0) + 1
                    first.setdefault(cat, decls)
            print(f"\r{compared} compared, {skipped} timed out, {sum(counts.values())} differ "
                  f"({time.time() - start:.0f} s)", end="", file=sys.stderr, flush=True)
        print(file=sys.stderr)
        print(f"compared {compared} files ({skipped} skipped on a timeout); old outcomes: {statuses}")
        print(f"discrepancies by kind: {counts or 'none'}")
        report = []
        for cat, decls in list(first.items())[:args.show]:
            small = shrink(pair, decls, cat)
            text = file_text(small)
            (o,), (n,) = pair.run([text])
            report.append({"kind": cat, "count": counts[cat], "text": text, "old": o, "new": n})
            print(f"\n=== {cat} ({counts[cat]} cases) ===\n{text}--- old:\n{json.dumps(o, indent=1)}"
                  f"\n--- new:\n{json.dumps(n, indent=1)}")
        if args.json:
            Path(args.json).write_text(json.dumps(report, indent=1))
    finally:
        pair.close()
    return 1 if counts else 0


if __name__ == "__main__":
    sys.exit(main())
