"""One-line documentation of every config field, read from the schema's own source.

A field's doc is its trailing comment or, failing that, the comment block right above it
(the way the dataclasses of this package are written), so the text a reader sees in
``pamrun/config/*.py`` is the text ``pamrun <command> --help`` prints.
"""

from __future__ import annotations

import ast
import dataclasses
import functools
import inspect
import io
import tokenize
from typing import Any


@functools.cache
def field_docs(cls: type) -> dict[str, str]:
    """Field name -> its one-line doc ('' when the source has none)."""
    source = inspect.getsource(cls)
    lines = source.splitlines()
    comments: dict[int, str] = {}  # 1-based line -> comment text
    for tok in tokenize.generate_tokens(io.StringIO(source).readline):
        if tok.type == tokenize.COMMENT:
            comments[tok.start[0]] = tok.string.lstrip("#").strip()
    body = ast.parse(source).body[0].body
    docs = {}
    for node in body:
        if not isinstance(node, ast.AnnAssign) or not isinstance(node.target, ast.Name):
            continue
        trailing = node.end_lineno in comments and not lines[node.end_lineno - 1].lstrip().startswith("#")
        text = comments[node.end_lineno] if trailing else ""
        if not text:  # the comment block heading this run of fields (no blank line in between)
            k = node.lineno - 1
            while k >= 1 and lines[k - 1].strip() and not lines[k - 1].lstrip().startswith("#"):
                k -= 1  # over the fields (and their continuation lines) above
            above = []
            while k >= 1 and lines[k - 1].lstrip().startswith("#"):
                above.insert(0, comments.get(k, ""))
                k -= 1
            text = " ".join(above)
        docs[node.target.id] = text
    return docs


def describe(cls: type, prefix: str = "", instance: Any = None) -> list[tuple[str, Any, str]]:
    """(full key, default, doc) of every leaf field of a config dataclass, nested ones expanded."""
    out = []
    instance = cls() if instance is None else instance
    docs = field_docs(cls)
    for f in dataclasses.fields(cls):
        value = getattr(instance, f.name)
        if dataclasses.is_dataclass(value):
            out += _within(describe(type(value), f"{prefix}{f.name}.", value), docs.get(f.name, ""))
        elif isinstance(value, dict) and value and all(dataclasses.is_dataclass(v) for v in value.values()):
            for name, sub in value.items():
                if any(isinstance(v, dict) for v in vars(sub).values()):  # one line each (e.g. perturbations)
                    out.append((f"{prefix}{f.name}.{name}", {k: v for k, v in vars(sub).items() if v},
                                docs.get(f.name, "")))
                else:
                    out += _within(describe(type(sub), f"{prefix}{f.name}.{name}.", sub), docs.get(f.name, ""))
        else:
            out.append((prefix + f.name, value, docs.get(f.name, "")))
    return out


def _within(rows: list[tuple[str, Any, str]], parent_doc: str) -> list[tuple[str, Any, str]]:
    """Fields of a per-joint table read as 'pulley radius [mm]; 0 = automatic: knee'."""
    if not parent_doc:
        return rows
    return [(key, value, f"{parent_doc}: {doc}" if doc else parent_doc) for key, value, doc in rows]
