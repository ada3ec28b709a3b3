"""The context of resolving one file: where problems are reported, which sorts are in scope.

Shared by the walk over names (:mod:`sessiontypes.expand`) and the resolution
of terms (:mod:`sessiontypes.resolve`), below both.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass, field

from . import syntax as s
from .errors import Diagnostic
from .location import Location
from .sorts import BUILTIN_SORTS, Field, Interaction, Sort, builtin_sort, record_sort

__all__ = ["Reporter", "SortTable"]

_TARGET = re.compile(
    r"^(?:[A-Za-z_][\w]*(?:\.[A-Za-z_]\w*)*:[A-Za-z_]\w*(?:\.[A-Za-z_]\w*)*"
    r"|ros:[A-Za-z_]\w*/(?:msg|srv|action)/[A-Za-z_]\w*)$"
)


@dataclass
class Reporter:
    """Collects diagnostics for one source file."""

    source: s.SourceFile
    diagnostics: list[Diagnostic] = field(default_factory=list)

    def error(self, location: Location, message: str, hint: str = "") -> None:
        self.diagnostics.append(
            Diagnostic("error", location, message, self.source.line(location.line), hint))

    def warning(self, location: Location, message: str) -> None:
        self.diagnostics.append(
            Diagnostic("warning", location, message, self.source.line(location.line)))


class SortTable:
    """The builtin sorts and the file's ``type`` declarations; records uses."""

    def __init__(self, declarations: Mapping[str, s.TypeDecl], reporter: Reporter) -> None:
        self.declared = dict(declarations)
        self.used: set[str] = set()
        self.reporter = reporter
        for decl in declarations.values():
            if not _TARGET.match(decl.target):
                reporter.error(decl.name.location,
                               f"type {decl.name.text} is bound to {decl.target!r}; expected "
                               "\"module:QualifiedName\" or \"ros:package/msg/Name\"")

    def is_sort(self, name: str) -> bool:
        return name in BUILTIN_SORTS or name in self.declared

    def sort(self, name: s.Name) -> Sort | None:
        """The sort called ``name``; reports an unknown sort and returns None."""
        if name.text in BUILTIN_SORTS:
            return builtin_sort(name.text)
        decl = self.declared.get(name.text)
        if decl is None:
            self.reporter.error(name.location, f"unknown sort '{name.text}'; expected a builtin "
                                "sort (int, nat, bool, str, float, bytes) or a declared type")
            return None
        self.used.add(name.text)
        return Sort(name.text, name.text, decl.target)

    def message(self, syntax: s.MessageSyntax) -> Interaction:
        """Apply the abbreviation rule: a bare sort name labels a value of that sort."""
        if syntax.fields is not None:
            return Interaction(syntax.label.text, self.record(syntax.label, syntax.fields))
        refinement = syntax.refinement
        if syntax.parens:
            if syntax.sort is None:
                return Interaction(syntax.label.text, None, self.is_sort(syntax.label.text))
            return Interaction(syntax.label.text, self.sort(syntax.sort), refinement=refinement)
        if self.is_sort(syntax.label.text):
            return Interaction(syntax.label.text, self.sort(syntax.label), refinement=refinement)
        if refinement is not None:
            self.reporter.error(refinement.location, f"a refinement constrains a payload, and label "
                                f"'{syntax.label.text}' carries none (it names no sort)")
        return Interaction(syntax.label.text)

    def record(self, label: s.Name, fields: tuple[s.FieldSyntax, ...]) -> Sort | None:
        """The record sort of named payloads; reports repeated field names and unknown sorts."""
        resolved: list[Field] = []
        seen: set[str] = set()
        for f in fields:
            if f.name.text in seen:
                self.reporter.error(f.name.location, f"duplicate field '{f.name.text}' in message "
                                    f"'{label.text}'")
            seen.add(f.name.text)
            sort = self.sort(f.sort)
            if sort is not None:
                resolved.append(Field(f.name.text, sort, f.refinement))
        if len(resolved) < len(fields) or len(seen) < len(fields):
            return None  # already reported
        return record_sort(tuple(resolved))

    def defined(self) -> dict[str, Sort]:
        return {name: Sort(name, name, d.target) for name, d in self.declared.items()}
