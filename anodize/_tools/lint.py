"""Isolation lint: what lets groups talk outside the protocol when they share a process.

With ``transport = "inproc"`` every group is a set of threads of one process,
so a module-level list, a lock or a ``global`` variable that roles of two
groups both use is a channel the protocol does not know about (the paper's
Fig. 12: threads talking outside the session). :func:`lint_system` reads the
source of each role function with :mod:`ast` (it never imports or runs it),
follows the functions it calls by name (within its module, through imports of
user modules, ``self.method`` in classes) and reports:

- every ``global`` statement in code a role runs;
- module-level mutable state (list, dict and set displays and comprehensions,
  ``list()``/``dict()``/``set()``, ``collections`` containers, numpy arrays,
  instances of the module's classes, class-level mutable attributes, and names
  that role code rebinds with ``global`` or whose attributes it assigns) that
  roles of two different groups touch: one finding per name and pair of groups,
  at the definition;
- the same for locks, queues, events and other ``threading``/``queue``/
  ``multiprocessing`` objects, which are "used as a back channel outside the protocol".

Constants, imported modules, functions and classes are not state.
"""

from __future__ import annotations

import ast
import importlib.machinery
import os
import sys
import sysconfig
from collections import defaultdict
from collections.abc import Iterator
from dataclasses import dataclass, field
from itertools import combinations
from pathlib import Path

from sessiontypes.limits import SOURCE, read_limited

from .config import ConfigError, SystemConfig

__all__ = ["Finding", "LintReport", "lint_system", "lint_report"]

_SYNC = {f"{module}.{name}" for module, names in {
    "threading": "Lock RLock Event Condition Semaphore BoundedSemaphore Barrier",
    "queue": "Queue SimpleQueue LifoQueue PriorityQueue",
    "multiprocessing": "Queue SimpleQueue JoinableQueue Value Array RawValue RawArray Lock RLock "
                       "Event Condition Semaphore BoundedSemaphore Barrier Pipe Manager",
    "asyncio": "Queue LifoQueue PriorityQueue Lock Event Condition Semaphore BoundedSemaphore",
}.items() for name in names.split()}
_MUTABLE = {"list", "dict", "set", "bytearray", "array.array", "io.StringIO", "io.BytesIO",
            "types.SimpleNamespace"} | {f"collections.{name}" for name in (
                "deque", "defaultdict", "OrderedDict", "Counter", "ChainMap")} | {
            f"numpy.{name}" for name in ("array", "zeros", "ones", "empty", "full", "arange",
                                         "zeros_like", "ones_like", "empty_like", "full_like")}
_DISPLAYS = {ast.List: "list", ast.ListComp: "list", ast.Dict: "dict", ast.DictComp: "dict",
             ast.Set: "set", ast.SetComp: "set"}
_IMMUTABLE_BASES = {"NamedTuple", "Enum", "IntEnum", "StrEnum", "Flag", "IntFlag", "tuple", "str",
                    "int", "float", "bytes", "frozenset"}
_RUNTIME = {"anodize", "sessiontypes"}  # the protocol's own channels are not a back channel
_USES_SHOWN = 3  # use sites listed per role in a message


@dataclass(frozen=True)
class Finding:
    """One isolation problem, at a place in a role's source.

    Attributes:
        path: the source file (relative to the working directory when inside it).
        line: 1-based line.
        col: 1-based column.
        role: the role the finding is about, or None when it concerns two groups
            (both named in the message).
        group: that role's group, or None.
        message: what is shared, by whom, and where it is used.
    """

    path: str
    line: int
    col: int
    role: str | None
    group: str | None
    message: str

    def __str__(self) -> str:
        return f"{self.path}:{self.line}:{self.col}: warning: {self.message}"


@dataclass(frozen=True)
class LintReport:
    """What :func:`lint_report` found, and which modules it read (display paths, sorted)."""

    findings: tuple[Finding, ...]
    modules: tuple[str, ...]


def lint_system(config: SystemConfig) -> list[Finding]:
    """The isolation findings for a system file's roles, sorted by place, without duplicates.

    Raises:
        ConfigError: a role's module cannot be found or parsed, or has no such function.
    """
    return list(lint_report(config).findings)


def lint_report(config: SystemConfig) -> LintReport:
    """:func:`lint_system`, with the modules read.

    Raises:
        ConfigError: a role's module cannot be found or parsed, or has no such function.
    """
    library = _Library(config)
    walk = _Walk(library)
    findings: set[Finding] = set()
    for group in config.groups.values():
        for role, reference in group.roles.items():
            findings |= walk.role(role, group.name, reference)
    findings |= _shared_state(config, library, walk)
    ordered = sorted(findings, key=lambda f: (f.path, f.line, f.col, f.message))
    return LintReport(tuple(ordered), tuple(sorted(m.display for m in library.read())))


# ---- reading modules ------------------------------------------------------------------------

@dataclass(frozen=True, order=True)
class _Site:
    path: str
    line: int
    col: int

    def __str__(self) -> str:
        return f"{self.path}:{self.line}:{self.col}"

    def short(self, path: str) -> str:
        """``line:col`` in the file ``path``, else the whole site."""
        return f"{self.line}:{self.col}" if path == self.path else str(self)


@dataclass
class _Module:
    """What lint needs to know about one module's top level."""

    name: str
    display: str
    is_package: bool
    functions: dict[str, ast.FunctionDef | ast.AsyncFunctionDef | ast.Lambda] = field(default_factory=dict)
    classes: dict[str, ast.ClassDef] = field(default_factory=dict)
    imports: dict[str, tuple[str, str | None]] = field(default_factory=dict)  # name -> (module, attr)
    sites: dict[str, _Site] = field(default_factory=dict)       # where each top-level name is bound
    values: dict[str, list[ast.expr]] = field(default_factory=dict)   # top-level names -> values
    state: dict[str, tuple[str, bool]] = field(default_factory=dict)  # name -> (kind, synchronization)

    def site(self, node: ast.AST) -> _Site:
        return _Site(self.display, getattr(node, "lineno", 1), getattr(node, "col_offset", 0) + 1)


class _Library:
    """Finds, parses and caches modules; only user code (not the standard library or
    installed packages) is followed from an import."""

    def __init__(self, config: SystemConfig) -> None:
        self.config = config
        self.search = [str(p) for p in config.pythonpath] + sys.path
        paths = sysconfig.get_paths()
        self.library_dirs = tuple({os.path.realpath(paths[k]) + os.sep
                                   for k in ("stdlib", "platstdlib", "purelib", "platlib") if k in paths})
        self.cache: dict[str, _Module | None] = {}

    def read(self) -> list[_Module]:
        return [m for m in self.cache.values() if m is not None]

    def role_module(self, name: str, key: str) -> _Module:
        origin = _find_source(name, self.search)
        if origin is None:
            raise ConfigError(str(self.config.path), key, f"cannot find the source of module {name} "
                              f"on the pythonpath ({', '.join(map(str, self.config.pythonpath))}) "
                              "or sys.path")
        module = self._load(name, origin, key)
        assert module is not None
        return module

    def module(self, name: str) -> _Module | None:
        """A user module by name, or None (not found, or library code)."""
        if name not in self.cache:
            origin = _find_source(name, self.search)
            if (origin is None or os.path.realpath(origin).startswith(self.library_dirs)
                    or name.partition(".")[0] in _RUNTIME):
                self.cache[name] = None
            else:
                return self._load(name, origin, None)
        return self.cache[name]

    def _load(self, name: str, origin: str, key: str | None) -> _Module | None:
        if name in self.cache:
            return self.cache[name]
        try:
            text = read_limited(origin, SOURCE).decode("utf-8")
            tree = ast.parse(text, origin)
        # ValueError: a NUL byte; RecursionError: nesting deeper than the compiler takes
        except (OSError, UnicodeDecodeError, SyntaxError, ValueError, RecursionError, MemoryError) as error:
            if key is None:
                self.cache[name] = None
                return None
            raise ConfigError(str(self.config.path), key,
                              f"cannot read module {name} ({_display(origin)}): {error}") from None
        module = _Module(name, _display(origin), Path(origin).name == "__init__.py")
        self.cache[name] = module
        _index(module, tree)
        for variable, values in module.values.items():
            kinds = [kind for value in values if (kind := self.classify(module, value))]
            if kinds:
                module.state[variable] = kinds[0]
        return module

    def classify(self, module: _Module, value: ast.expr) -> tuple[str, bool] | None:
        """(kind, is a synchronization object) for a mutable value; None for anything else."""
        if type(value) in _DISPLAYS:
            return _DISPLAYS[type(value)], False
        if isinstance(value, ast.Tuple):
            inner = next((k for e in value.elts if (k := self.classify(module, e))), None)
            return (f"tuple holding a {inner[0]}", inner[1]) if inner else None
        if not isinstance(value, ast.Call):
            return None
        dotted = _dotted(module, value.func)
        if dotted in _SYNC:
            return dotted, True
        if dotted in _MUTABLE:
            return dotted, False
        if isinstance(value.func, ast.Name | ast.Attribute):
            target = self.resolve_expr(module, value.func)
            if target and target.kind == "class" and not _immutable(target.module.classes[target.name]):
                return f"{target.name} instance", False
        return None

    def resolve_expr(self, module: _Module, node: ast.expr) -> _Target | None:
        if isinstance(node, ast.Name):
            return self.resolve(module, node.id)
        if isinstance(node, ast.Attribute):
            base = self.resolve_expr(module, node.value)
            if base and base.kind == "module":
                return self.resolve(base.module, node.attr)
        return None

    def resolve(self, module: _Module, name: str, depth: int = 0) -> _Target | None:
        """What a top-level name of ``module`` is: a function, class, module or variable."""
        if name in module.functions:
            return _Target("function", module, name)
        if name in module.classes:
            return _Target("class", module, name)
        if name in module.imports:
            source, attribute = module.imports[name]
            if attribute is None:
                imported = self.module(source)
                return _Target("module", imported, "") if imported else None
            if submodule := self.module(f"{source}.{attribute}"):
                return _Target("module", submodule, "")
            imported = self.module(source)
            return self.resolve(imported, attribute, depth + 1) if imported and depth < 8 else None
        if name in module.sites:
            return _Target("variable", module, name)
        if module.is_package and (submodule := self.module(f"{module.name}.{name}")):
            return _Target("module", submodule, "")  # 'import a.b' then 'a.b.x'
        return None


@dataclass(frozen=True)
class _Target:
    kind: str  # "function" | "class" | "module" | "variable"
    module: _Module
    name: str


def _find_source(name: str, search: list[str]) -> str | None:
    """The .py file of module ``name``, found without importing any package."""
    path = search
    spec = None
    parts = name.split(".")
    for index in range(len(parts)):
        try:
            spec = importlib.machinery.PathFinder.find_spec(".".join(parts[:index + 1]), path)
        except (ImportError, ValueError):
            return None
        if spec is None:
            return None
        path = list(spec.submodule_search_locations or [])
    origin = spec.origin if spec else None
    return origin if origin and origin.endswith(".py") else None


def _display(path: str) -> str:
    relative = os.path.relpath(path)
    return path if relative.startswith("..") else relative


def _top_level(body: list[ast.stmt]) -> Iterator[ast.stmt]:
    """Statements run at import: the body and the blocks of if/try/with/for/while/match."""
    for statement in body:
        yield statement
        if isinstance(statement, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
            continue
        for name in ("body", "orelse", "finalbody"):
            yield from _top_level(getattr(statement, name, []))
        for handler in getattr(statement, "handlers", []):
            yield from _top_level(handler.body)
        for case in getattr(statement, "cases", []):
            yield from _top_level(case.body)


def _index(module: _Module, tree: ast.Module) -> None:
    for statement in _top_level(tree.body):
        match statement:
            case ast.FunctionDef() | ast.AsyncFunctionDef():
                module.functions[statement.name] = statement
                module.sites.setdefault(statement.name, module.site(statement))
            case ast.ClassDef():
                _index_class(module, statement, statement.name)
            case ast.Import():
                for alias in statement.names:
                    if alias.asname:
                        module.imports[alias.asname] = (alias.name, None)
                    else:
                        top = alias.name.partition(".")[0]
                        module.imports[top] = (top, None)
            case ast.ImportFrom():
                source = _absolute(module, statement)
                for alias in statement.names:
                    if alias.name != "*":
                        module.imports[alias.asname or alias.name] = (source, alias.name)
            case ast.Assign(targets=targets, value=value):
                for target in targets:
                    _bind(module, target, value, "")
            case ast.AnnAssign(target=target, value=value) | ast.AugAssign(target=target, value=value):
                if value is not None:
                    _bind(module, target, value, "")
    for node in ast.walk(tree):  # names only ever bound by 'global' in a function
        if isinstance(node, ast.Global):
            for name in node.names:
                module.sites.setdefault(name, module.site(node))


def _index_class(module: _Module, node: ast.ClassDef, qualified: str) -> None:
    module.classes[qualified] = node
    module.sites.setdefault(qualified, module.site(node))
    for statement in node.body:
        match statement:
            case ast.FunctionDef() | ast.AsyncFunctionDef():
                module.functions[f"{qualified}.{statement.name}"] = statement
            case ast.ClassDef():
                _index_class(module, statement, f"{qualified}.{statement.name}")
            case ast.Assign(targets=targets, value=value):
                for target in targets:
                    _bind(module, target, value, f"{qualified}.")
            case ast.AnnAssign(target=target, value=value) if value is not None:
                _bind(module, target, value, f"{qualified}.")


def _bind(module: _Module, target: ast.expr, value: ast.expr, prefix: str) -> None:
    if isinstance(target, ast.Name):
        name = prefix + target.id
        module.sites.setdefault(name, module.site(target))
        module.values.setdefault(name, []).append(value)
        if not prefix and isinstance(value, ast.Lambda):
            module.functions.setdefault(name, value)
    elif isinstance(target, ast.Tuple | ast.List):
        values = value.elts if isinstance(value, ast.Tuple | ast.List) else None
        for index, element in enumerate(target.elts):
            same_length = values is not None and len(values) == len(target.elts)
            _bind(module, element, values[index] if values and same_length else ast.Constant(None),
                  prefix)


def _absolute(module: _Module, node: ast.ImportFrom) -> str:
    if not node.level:
        return node.module or ""
    package = module.name if module.is_package else module.name.rpartition(".")[0]
    for _ in range(node.level - 1):
        package = package.rpartition(".")[0]
    return f"{package}.{node.module}" if node.module else package


def _dotted(module: _Module, node: ast.expr) -> str | None:
    """``deque`` -> ``collections.deque`` after ``from collections import deque``; builtins stay."""
    if isinstance(node, ast.Name):
        if node.id in module.imports:
            source, attribute = module.imports[node.id]
            return f"{source}.{attribute}" if attribute else source
        return None if node.id in module.sites or node.id in module.functions else node.id
    if isinstance(node, ast.Attribute):
        base = _dotted(module, node.value)
        return f"{base}.{node.attr}" if base else None
    return None


def _immutable(node: ast.ClassDef) -> bool:
    for base in node.bases:
        name = base.attr if isinstance(base, ast.Attribute) else getattr(base, "id", "")
        if name in _IMMUTABLE_BASES:
            return True
    for decorator in node.decorator_list:
        if isinstance(decorator, ast.Call) and any(
                k.arg == "frozen" and isinstance(k.value, ast.Constant) and k.value.value is True
                for k in decorator.keywords):
            return True
        name = decorator.attr if isinstance(decorator, ast.Attribute) else getattr(decorator, "id", "")
        if name == "frozen":  # attrs.frozen
            return True
    return False


# ---- walking role code ----------------------------------------------------------------------

Key = tuple[str, str]  # (module name, top-level name or Class.attribute)


@dataclass(frozen=True)
class _Touch:
    role: str
    group: str
    site: _Site
    how: str


class _Walk:
    """Follows each role's code and records what module state it touches."""

    def __init__(self, library: _Library) -> None:
        self.library = library
        self.touches: dict[Key, set[_Touch]] = defaultdict(set)
        self.dynamic: dict[Key, str] = {}  # state made by role code: key -> kind

    def role(self, role: str, group: str, reference: str) -> set[Finding]:
        key = f"groups.{group}.roles.{role}"
        module_name, _, qualified = reference.partition(":")
        module = self.library.role_module(module_name, key)
        start = self._entry(module, qualified, key)
        if start is None:
            site = module.sites.get(qualified.partition(".")[0], _Site(module.display, 1, 1))
            return {Finding(site.path, site.line, site.col, role, group,
                            f"role {role}: {reference} is not a function anodize can read, so its "
                            "code was not checked")}
        findings: set[Finding] = set()
        todo = [start]
        seen: set[tuple[str, str, Key | None]] = set()
        while todo:
            module, name, self_key = todo.pop()
            if (module.name, name, self_key) in seen:
                continue
            seen.add((module.name, name, self_key))
            visit = _Visit(self, module, name, self_key, role, group)
            findings |= visit.run()
            todo.extend(visit.calls)
        return findings

    def _entry(self, module: _Module, qualified: str,
               key: str) -> tuple[_Module, str, Key | None] | None:
        if qualified in module.functions:
            return module, qualified, None
        first, _, rest = qualified.partition(".")
        state = module.state.get(first)
        if rest and state and state[0].endswith(" instance"):  # 'module:robot.run'
            cls = state[0].removesuffix(" instance")
            if f"{cls}.{rest}" in module.functions:
                return module, f"{cls}.{rest}", (module.name, first)
        target = self.library.resolve(module, first)
        if target is None and first in module.imports:  # library code
            return None
        if target is None:
            raise ConfigError(str(self.library.config.path), key,
                              f"module {module.name} ({module.display}) has no {qualified}")
        wanted = f"{target.name}.{rest}" if rest else target.name
        if target.kind in ("function", "class") and wanted in target.module.functions:
            return target.module, wanted, None
        return None

    def touch(self, key: Key, touch: _Touch) -> None:
        self.touches[key].add(touch)


class _Visit:
    """One function of a role's code: its global statements, touches and calls."""

    def __init__(self, walk: _Walk, module: _Module, name: str, self_key: Key | None,
                 role: str, group: str) -> None:
        self.walk = walk
        self.library = walk.library
        self.module = module
        self.name = name
        self.function = module.functions[name]
        self.self_key = self_key
        self.role = role
        self.group = group
        self.calls: list[tuple[_Module, str, Key | None]] = []
        self.cls = name.rpartition(".")[0] if name.rpartition(".")[0] in module.classes else None
        self.parents = {child: node for node in ast.walk(self.function)
                        for child in ast.iter_child_nodes(node)}
        self.declared = {n for node in ast.walk(self.function) if isinstance(node, ast.Global)
                         for n in node.names}
        self.locals = _local_names(self.function) - self.declared
        arguments = self.function.args.posonlyargs + self.function.args.args
        self.receiver = arguments[0].arg if self.cls and arguments and not _static(self.function) else None

    def run(self) -> set[Finding]:
        findings = set()
        for node in ast.walk(self.function):
            if isinstance(node, ast.Global):
                findings |= self.global_statement(node)
            elif isinstance(node, ast.Name) and node.id not in self.locals:
                self.name_use(node)
            elif isinstance(node, ast.Attribute):
                self.attribute_use(node)
        return findings

    def global_statement(self, node: ast.Global) -> set[Finding]:
        site = self.module.site(node)
        for name in node.names:
            self.walk.dynamic.setdefault((self.module.name, name), "variable")
        return {Finding(site.path, site.line, site.col, self.role, self.group,
                        f"global statement: role {self.role} (group {self.group}) rebinds module-level "
                        f"{name}, which every thread of the process shares outside the protocol")
                for name in node.names}

    def name_use(self, node: ast.Name) -> None:
        if node.id in self.declared:
            self.record((self.module.name, node.id), node)
            return
        target = self.library.resolve(self.module, node.id)
        if target is not None:
            self.use(target, node)

    def attribute_use(self, node: ast.Attribute) -> None:
        if isinstance(node.value, ast.Name) and node.value.id == self.receiver:
            self.member_use(node)
            return
        target = self.base_target(node.value)
        if target is None:
            return
        if target.kind == "module":
            member = self.library.resolve(target.module, node.attr)
            if member is not None and member.kind != "variable":
                self.use(member, node)
                return
            if isinstance(node.ctx, ast.Store | ast.Del):  # state even if it was a constant
                self.walk.dynamic.setdefault((target.module.name, node.attr), "module attribute")
            self.record((target.module.name, node.attr), node)
        elif target.kind == "class":
            qualified = f"{target.name}.{node.attr}"
            if qualified in target.module.functions:
                self.calls.append((target.module, qualified, None))
                return
            if isinstance(node.ctx, ast.Store | ast.Del):
                self.walk.dynamic.setdefault((target.module.name, qualified), "class attribute")
            self.record((target.module.name, qualified), node)
        elif target.kind == "variable" and isinstance(node.ctx, ast.Store | ast.Del):
            self.walk.dynamic.setdefault((target.module.name, target.name), "object")
        elif target.kind == "variable":
            state = target.module.state.get(target.name)
            cls = state[0].removesuffix(" instance") if state else ""
            if f"{cls}.{node.attr}" in target.module.functions:  # module_object.method()
                self.calls.append((target.module, f"{cls}.{node.attr}", (target.module.name, target.name)))

    def base_target(self, node: ast.expr) -> _Target | None:
        """What ``node`` in ``node.attr`` is: a module-level name, or a chain through modules."""
        if isinstance(node, ast.Name):
            return None if node.id in self.locals else self.library.resolve(self.module, node.id)
        if isinstance(node, ast.Attribute):
            base = self.base_target(node.value)
            if base is not None and base.kind == "module":
                return self.library.resolve(base.module, node.attr)
        return None

    def member_use(self, node: ast.Attribute) -> None:
        """``self.x`` / ``cls.x`` in a method of class ``self.cls``."""
        qualified = f"{self.cls}.{node.attr}"
        if qualified in self.module.functions:
            self.calls.append((self.module, qualified, self.self_key))
        elif self.self_key is not None:  # the role is a method of a module-level object
            self.record(self.self_key, node.value)
        elif qualified in self.module.state or _is_classmethod(self.function):
            if isinstance(node.ctx, ast.Store | ast.Del):
                self.walk.dynamic.setdefault((self.module.name, qualified), "class attribute")
            self.record((self.module.name, qualified), node)

    def use(self, target: _Target, node: ast.Name | ast.Attribute) -> None:
        if target.kind == "function":
            self.calls.append((target.module, target.name, None))
        elif target.kind == "class" and self.instantiates(node):
            prefix = f"{target.name}."  # its methods run on this role's thread
            self.calls.extend((target.module, name, None) for name in target.module.functions
                              if name.startswith(prefix) and "." not in name[len(prefix):])
        elif target.kind == "variable":
            self.record((target.module.name, target.name), node)

    def instantiates(self, node: ast.expr) -> bool:
        parent = self.parents.get(node)
        return isinstance(parent, ast.Call) and parent.func is node

    def record(self, key: Key, node: ast.expr) -> None:
        self.walk.touch(key, _Touch(self.role, self.group, self.module.site(node), self.how(node)))

    def how(self, node: ast.expr) -> str:
        if isinstance(getattr(node, "ctx", None), ast.Store | ast.Del):
            return "assigns"
        parent = self.parents.get(node)
        if isinstance(parent, ast.Attribute) and parent.value is node:
            if isinstance(parent.ctx, ast.Store | ast.Del):
                return f"sets .{parent.attr}"
            grandparent = self.parents.get(parent)
            if isinstance(grandparent, ast.Call) and grandparent.func is parent:
                return f"calls .{parent.attr}()"
            return f"reads .{parent.attr}"
        if isinstance(parent, ast.Subscript) and parent.value is node:
            return "changes an item" if isinstance(parent.ctx, ast.Store | ast.Del) else "reads an item"
        if isinstance(parent, ast.withitem):
            return "enters it (with)"
        return "uses"


def _local_names(function: ast.AST) -> set[str]:
    names = set()
    for node in ast.walk(function):
        if isinstance(node, ast.arg):
            names.add(node.arg)
        elif isinstance(node, ast.Name) and isinstance(node.ctx, ast.Store | ast.Del):
            names.add(node.id)
        elif isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef) and node is not function:
            names.add(node.name)
        elif isinstance(node, ast.Import | ast.ImportFrom):
            names.update((a.asname or a.name).partition(".")[0] for a in node.names)
        elif isinstance(node, ast.ExceptHandler | ast.MatchAs | ast.MatchStar) and node.name:
            names.add(node.name)
        elif isinstance(node, ast.MatchMapping) and node.rest:
            names.add(node.rest)
    return names


def _decorators(function: ast.AST) -> set[str]:
    return {getattr(d, "id", getattr(d, "attr", "")) for d in getattr(function, "decorator_list", [])}


def _static(function: ast.AST) -> bool:
    return "staticmethod" in _decorators(function)


def _is_classmethod(function: ast.AST) -> bool:
    return "classmethod" in _decorators(function)


# ---- findings about shared state ------------------------------------------------------------

def _shared_state(config: SystemConfig, library: _Library, walk: _Walk) -> set[Finding]:
    order = {name: index for index, name in enumerate(config.groups)}
    findings = set()
    for (module_name, name), uses in walk.touches.items():
        module = library.cache[module_name]
        assert module is not None
        kind = module.state.get(name)
        if kind is None and (module_name, name) in walk.dynamic:
            kind = (walk.dynamic[module_name, name], False)
        if kind is None:
            continue
        by_group: dict[str, list[_Touch]] = defaultdict(list)
        for use in uses:
            by_group[use.group].append(use)
        site = module.sites.get(name) or min(use.site for use in uses)
        shown = f"{module_name}.{name}" if kind[0] == "module attribute" else name
        for first, second in combinations(sorted(by_group, key=order.__getitem__), 2):
            findings.add(Finding(site.path, site.line, site.col, None, None,
                                 _message(kind, shown, site.path, first, second, by_group)))
    return findings


def _message(kind: tuple[str, bool], name: str, path: str, first: str, second: str,
             by_group: dict[str, list[_Touch]]) -> str:
    uses = []
    roles = {}
    for group in (first, second):
        per_role: dict[str, list[_Touch]] = defaultdict(list)
        for use in sorted(by_group[group], key=lambda u: (u.role, u.site)):
            per_role[use.role].append(use)
        roles[group] = ", ".join(per_role)
        for role, role_uses in per_role.items():
            shown = ", ".join(f"{u.site.short(path)} {u.how}" for u in role_uses[:_USES_SHOWN])
            more = len(role_uses) - _USES_SHOWN
            uses.append(f"{role}: {shown}" + (f" and {more} more" if more > 0 else ""))
    what = (f"{kind[0]} {name} is shared by group {first} ({roles[first]}) and group {second} "
            f"({roles[second]})")
    where = "; ".join(uses)
    if kind[1]:
        return f"{what}: used as a back channel outside the protocol ({where})"
    return f"{what} outside the protocol ({where})"
