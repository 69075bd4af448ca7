"""Load a YAML file into a pydantic model, reporting problems as file:line and field.

PyYAML's composer keeps the line of every node, so each pydantic error location (a path of keys
and indices) is mapped back to the line where that value (or its parent) was written.

Bounds, checked before the parts of PyYAML that recurse or allocate: at most
:data:`MAX_BYTES` of text; :data:`MAX_DEPTH` levels of nesting and :data:`MAX_EXPANDED_NODES`
values, counted on the parser's events (which do not recurse) before the document is built,
and again once aliases are expanded, on the built node graph without expanding it (where an
alias inside the value it names, a loop, is refused too); integers of at most
:data:`MAX_INT_DIGITS` digits. A value its explicit tag cannot convert (``!!int abc``) is
refused at its line. YAML 1.1's base-60 numbers (``1:30`` read as 90) and its
integers in octal (``017`` read as 15), hexadecimal (``0x10``) or binary (``0b11``) are refused
with their line: write the number in decimal, or quote the text. So is a merge of several
mappings (``<<: [*a, *b]``), whose precedence PyYAML reverses from YAML's (the last one wins
instead of the first): merge one mapping, or write the values.
"""

from __future__ import annotations

import datetime
from collections.abc import Iterator
from pathlib import Path
from typing import Any, TypeVar

import yaml
from pydantic import BaseModel, ValidationError

from labrig.core.errors import InputFileError, InputIssue
from labrig.core.textfile import read_bytes_bounded

M = TypeVar("M", bound=BaseModel)
MAX_BYTES = 5_000_000
#: a document whose aliases expand to more YAML nodes than this is refused ("billion laughs")
MAX_EXPANDED_NODES = 200_000
#: the deepest nesting of mappings and lists read (PyYAML's composer recurses per level)
MAX_DEPTH = 64
#: the most digits an integer may have (Python refuses to convert more than 4300)
MAX_INT_DIGITS = 100


class BoundedConstructor(yaml.constructor.SafeConstructor):
    """PyYAML's safe constructor, refusing base-60 numbers and integers of more than
    :data:`MAX_INT_DIGITS` digits, and naming the line of a date that does not exist (a
    ``ConstructorError`` with the value's line). The first base of a loader class
    (:class:`PythonLoader`, :data:`BoundedLoader`), before PyYAML's safe loader."""

    def refuse_odd_number(self, node: yaml.ScalarNode) -> None:
        """A base-60 number, an integer written in octal (a leading zero), hexadecimal or
        binary, or an integer with too many digits: ``ConstructorError``."""
        value = str(self.construct_scalar(node))
        if ":" in value:
            raise yaml.constructor.ConstructorError(
                None,
                None,
                f"{value!r} is a base-60 number in YAML 1.1; write the number, "
                "or quote it if it is text",
                node.start_mark,
            )
        body = value.replace("_", "").lstrip("+-").lower()
        if body.startswith(("0x", "0b")) or (len(body) > 1 and body.startswith("0")):
            kind = {"0x": "a hexadecimal", "0b": "a binary"}.get(body[:2], "an octal")
            raise yaml.constructor.ConstructorError(
                None,
                None,
                f"{value!r} is {kind} number in YAML 1.1 (read as "
                f"{super().construct_yaml_int(node)}); write the number in decimal without "
                "leading zeros, or quote it if it is text",
                node.start_mark,
            )
        digits = sum(c.isdigit() for c in value)
        if digits > MAX_INT_DIGITS:
            raise yaml.constructor.ConstructorError(
                None,
                None,
                f"a number with {digits} digits (at most {MAX_INT_DIGITS} are read)",
                node.start_mark,
            )

    def construct_yaml_int(self, node: yaml.ScalarNode) -> int:
        self.refuse_odd_number(node)
        return super().construct_yaml_int(node)

    def construct_yaml_float(self, node: yaml.ScalarNode) -> float:
        if ":" in str(self.construct_scalar(node)):
            self.refuse_odd_number(node)
        return super().construct_yaml_float(node)

    def construct_object(self, node: yaml.Node, deep: bool = False) -> Any:
        """PyYAML's, with a value its tag cannot convert (``!!int abc``, ``!!bool maybe``,
        ``!!timestamp never``: PyYAML's converters raise ``ValueError``, ``KeyError``,
        ``IndexError``, ...) refused as a ``ConstructorError`` at the value's line."""
        try:
            return super().construct_object(node, deep)
        except (ValueError, TypeError, KeyError, IndexError, AttributeError, OverflowError):
            tag = str(node.tag).rsplit(":", 1)[-1]
            shown = repr(node.value)[:60] if isinstance(node, yaml.ScalarNode) else "this value"
            raise yaml.constructor.ConstructorError(
                None, None, f"{shown} cannot be read as !!{tag}", node.start_mark
            ) from None

    def construct_yaml_timestamp(self, node: yaml.ScalarNode) -> datetime.date:
        try:
            return super().construct_yaml_timestamp(node)
        except ValueError as e:  # 2026-13-45: datetime's own message, e.g. "month must be ..."
            raise yaml.constructor.ConstructorError(
                None, None, f"{self.construct_scalar(node)!r} is not a date ({e})", node.start_mark
            ) from None


class PythonLoader(BoundedConstructor, yaml.SafeLoader):
    """The bounded safe loader on PyYAML's own parser, written in Python."""


def _constructors(cls: Any) -> None:
    """Register :class:`BoundedConstructor`'s checks on the loader class ``cls``."""
    cls.add_constructor("tag:yaml.org,2002:int", BoundedConstructor.construct_yaml_int)
    cls.add_constructor("tag:yaml.org,2002:float", BoundedConstructor.construct_yaml_float)
    cls.add_constructor("tag:yaml.org,2002:timestamp", BoundedConstructor.construct_yaml_timestamp)


_constructors(PythonLoader)


#: a loader class: :class:`BoundedConstructor` on one of PyYAML's safe loaders
LoaderClass = type[BoundedConstructor]

if getattr(yaml, "__with_libyaml__", False):

    class LibyamlLoader(BoundedConstructor, yaml.CSafeLoader):
        """The bounded safe loader on libyaml's parser (PyYAML's C extension)."""

    #: the loader :func:`read_yaml` and :func:`load_text` use: on libyaml's parser where
    #: PyYAML has it (its wheels on PyPI do), which takes about a fifteenth of the CPU of
    #: PyYAML's parser in Python (:class:`PythonLoader`, used without it). Both read the same
    #: documents to the same data and name the same lines (the tests compare them); their
    #: syntax errors are worded differently, and libyaml takes a tab for the space after
    #: ``key:`` (YAML 1.2 allows it).
    _constructors(LibyamlLoader)
    BoundedLoader: LoaderClass = LibyamlLoader
else:  # pragma: no cover - PyYAML built without libyaml
    BoundedLoader = PythonLoader


def _event_issue(loader: Any, name: str) -> InputIssue | None:
    """Nesting deeper than :data:`MAX_DEPTH`, or more than :data:`MAX_EXPANDED_NODES` values
    before any alias is expanded, found on the parser's events (no recursion, no node kept);
    libyaml's own nesting limit (1000 levels, reached first when the brackets of one line run
    that deep) is reported as nesting too."""
    depth = values = 0
    try:
        while loader.check_event():
            event = loader.get_event()
            if isinstance(event, yaml.CollectionStartEvent | yaml.ScalarEvent | yaml.AliasEvent):
                values += 1
                if values > MAX_EXPANDED_NODES:
                    return _too_many(name, _line(event.start_mark), aliases=False)
            if isinstance(event, yaml.CollectionStartEvent):
                depth += 1
                if depth > MAX_DEPTH:
                    return _too_deep(name, _line(event.start_mark))
            elif isinstance(event, yaml.CollectionEndEvent):
                depth -= 1
    except yaml.MarkedYAMLError as e:
        if "maximum nesting depth" not in str(e.problem):
            raise
        return _too_deep(name, _line(e.problem_mark))
    return None


def _line(mark: Any) -> int | None:
    return mark.line + 1 if mark is not None else None


def _too_many(name: str, line: int | None, aliases: bool) -> InputIssue:
    what = "aliases expand this document to" if aliases else "this document has"
    return InputIssue(name, line, "", f"{what} more than {MAX_EXPANDED_NODES} values")


def _too_deep(name: str, line: int | None) -> InputIssue:
    return InputIssue(name, line, "", f"nested more than {MAX_DEPTH} levels deep (lists, mappings)")


def _compose(text: str, name: str, loader_class: LoaderClass) -> tuple[yaml.Node | None, object]:
    """The document's node tree and data, each bound checked before the step it protects
    (module docstring); PyYAML's own errors propagate as ``YAMLError``."""
    loader: Any = loader_class(text)  # type: ignore[call-arg]
    try:
        deep = _event_issue(loader, name)
    except (ValueError, OverflowError) as e:  # PyYAML's scanner on odd escapes ("\U9999...")
        raise _unreadable(name, loader, e) from None
    finally:
        loader.dispose()
    if deep is not None:
        raise InputFileError([deep])
    loader = loader_class(text)  # type: ignore[call-arg]
    try:
        node = loader.get_single_node()
        bomb = _expanded_issue(node, name) if node is not None else None
        if bomb is not None:
            raise InputFileError([bomb])
        refused = (
            duplicate_key_issues(node, name) + merge_list_issues(node, name)
            if node is not None
            else []
        )
        if refused:
            raise InputFileError(refused)
        data = loader.construct_document(node) if node is not None else None
    except (ValueError, OverflowError) as e:
        raise _unreadable(name, loader, e) from None
    finally:
        loader.dispose()
    return node, data


def _unreadable(name: str, loader: Any, e: Exception) -> InputFileError:
    """A value PyYAML's Python scanner fails on (``"\\U99999999"``: ``chr`` refuses it), at the
    scanner's line; libyaml's parser refuses such text itself, as a syntax error."""
    mark = loader.get_mark() if hasattr(loader, "get_mark") else None
    line = mark.line + 1 if mark is not None else None
    return InputFileError([InputIssue(name, line, "", f"YAML error: cannot read this ({e})")])


def _children(node: yaml.Node) -> list[yaml.Node]:
    if isinstance(node, yaml.MappingNode):
        return [v for kv in node.value for v in kv]
    if isinstance(node, yaml.SequenceNode):
        return list(node.value)
    return []


def _expanded_issue(root: yaml.Node, name: str) -> InputIssue | None:
    """Refuse YAML whose aliases (``*name``) make a loop (an alias inside the value it names:
    ``a: &x [*x]``), nest deeper than :data:`MAX_DEPTH` levels once expanded (anchors each
    wrapping the one before in lists) or expand to more than :data:`MAX_EXPANDED_NODES` values
    ("billion laughs").

    Measures the alias-expanded tree without expanding it: a depth-first walk of the shared
    node graph (no recursion), each node's expanded size and depth computed once, after its
    children's; a child still open on the walk's path is a loop. Before anything walks or
    validates the expanded data."""
    size: dict[int, int] = {}
    depth: dict[int, int] = {}
    open_: set[int] = set()
    stack: list[tuple[yaml.Node, list[yaml.Node] | None]] = [(root, None)]  # kids: closing
    while stack:
        node, kids = stack.pop()
        key = id(node)
        if kids is not None:
            open_.discard(key)
            size[key] = 1 + sum(size[id(k)] for k in kids)
            level = 1 if isinstance(node, yaml.CollectionNode) else 0
            depth[key] = level + max((depth[id(k)] for k in kids), default=0)
            if size[key] > MAX_EXPANDED_NODES:
                return _too_many(name, _line(node.start_mark), aliases=True)
            if depth[key] > MAX_DEPTH:
                return _too_deep(name, _line(node.start_mark))
            continue
        if key in size:
            continue
        open_.add(key)
        kids = _children(node)
        stack.append((node, kids))
        for k in kids:
            if id(k) in open_:
                msg = "an alias inside the value it names (a loop): write the value out"
                return InputIssue(name, _line(k.start_mark), "", msg)
            if id(k) not in size:
                stack.append((k, None))
    return None


def _field(path: tuple) -> str:
    return ".".join(str(x) if isinstance(x, str) else f"[{x}]" for x in path).replace(".[", "[")


def _mappings(root: yaml.Node) -> Iterator[tuple[yaml.MappingNode, tuple]]:
    """Every mapping of the composed document once (a node an alias shares is visited once),
    with its key path; no recursion."""
    stack: list[tuple[yaml.Node | None, tuple]] = [(root, ())]
    seen: set[int] = set()
    while stack:
        node, path = stack.pop()
        if node is None or id(node) in seen:
            continue
        seen.add(id(node))
        if isinstance(node, yaml.MappingNode):
            yield node, path
            for k, v in node.value:
                stack.append((v, (*path, k.value if isinstance(k, yaml.ScalarNode) else None)))
        elif isinstance(node, yaml.SequenceNode):
            stack.extend((v, (*path, i)) for i, v in enumerate(node.value))


def duplicate_key_issues(root: yaml.Node, name: str) -> list[InputIssue]:
    """Every key repeated within one mapping (YAML loaders silently keep the last one)."""
    out: list[InputIssue] = []
    for node, path in _mappings(root):
        keys = set()
        for k, _v in node.value:
            key = k.value if isinstance(k, yaml.ScalarNode) else None
            if key is not None and key in keys:
                msg = "this key is given twice in the same mapping"
                out.append(InputIssue(name, k.start_mark.line + 1, _field((*path, key)), msg))
            keys.add(key)
    return sorted(out, key=lambda i: i.line or 0)


def merge_list_issues(root: yaml.Node, name: str) -> list[InputIssue]:
    """Every merge key given a list of several mappings (``<<: [*a, *b]``): YAML says the
    first mapping's value wins where they share a key, PyYAML takes the last."""
    msg = (
        "a merge of several mappings (<<: [...]): YAML gives the first one's values precedence "
        "and PyYAML the last one's; merge one mapping (<<: *name) and write the values that "
        "differ"
    )
    out = [
        InputIssue(name, k.start_mark.line + 1, _field(path), msg)
        for node, path in _mappings(root)
        for k, v in node.value
        if k.tag == "tag:yaml.org,2002:merge"
        and isinstance(v, yaml.SequenceNode)
        and len(v.value) > 1
    ]
    return sorted(out, key=lambda i: i.line or 0)


def line_index(node: yaml.Node, path: tuple = (), out: dict | None = None) -> dict:
    """Map every key path in the YAML document to its 1-based line number."""
    out = {} if out is None else out
    out[path] = node.start_mark.line + 1
    if isinstance(node, yaml.MappingNode):
        for k, v in node.value:
            key = k.value if isinstance(k, yaml.ScalarNode) else str(k.value)
            out[(*path, key)] = k.start_mark.line + 1
            line_index(v, (*path, key), out)
            out[(*path, key)] = k.start_mark.line + 1
    elif isinstance(node, yaml.SequenceNode):
        for i, v in enumerate(node.value):
            line_index(v, (*path, i), out)
    return out


def _line_for(loc: tuple, lines: dict) -> int | None:
    path = tuple(loc)
    while path:
        if path in lines:
            return lines[path]
        path = path[:-1]
    return lines.get(())


def read_yaml(path: Path | str, loader: LoaderClass | None = None) -> tuple[object, dict, str]:
    """Parse a YAML file: ``(data, line_index, text)``; syntax problems raise InputFileError.
    ``loader``: the loader class (default :data:`BoundedLoader`)."""
    p = Path(path)
    name = str(path)
    try:
        raw = read_bytes_bounded(p, MAX_BYTES)
    except OSError as e:
        raise InputFileError([InputIssue(name, None, "", f"cannot read file: {e.strerror}")]) from e
    except ValueError as e:
        msg = f"file is too large for a YAML file ({e})"
        raise InputFileError([InputIssue(name, None, "", msg)]) from None
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as e:
        line = raw[: e.start].count(b"\n") + 1
        msg = "not a text file (invalid UTF-8); expected a YAML file"
        raise InputFileError([InputIssue(name, line, "", msg)]) from e
    if "\x00" in text:
        line = text[: text.index("\x00")].count("\n") + 1
        raise InputFileError([InputIssue(name, line, "", "binary data in a YAML file")])
    node, data = _parse(text, name, loader)
    lines = line_index(node) if node is not None else {}
    return data, lines, text


def load_text(text: str, name: str = "<text>", loader: LoaderClass | None = None) -> object:
    """Parse YAML text with the bounds of :func:`read_yaml` (a recorded protocol or rig text,
    for example); problems raise InputFileError naming ``name``."""
    if len(text) > MAX_BYTES:
        raise InputFileError([InputIssue(name, None, "", "text is too large for YAML")])
    return _parse(text, name, loader)[1]


def _parse(
    text: str, name: str, loader: LoaderClass | None = None
) -> tuple[yaml.Node | None, object]:
    """:func:`_compose` with every failure as an InputFileError naming the line."""
    try:
        return _compose(text, name, loader or BoundedLoader)
    except yaml.constructor.ConstructorError as e:
        line = _line_in(text, e.problem_mark)
        raise InputFileError([InputIssue(name, line, "", str(e.problem))]) from None
    except yaml.MarkedYAMLError as e:
        mark = e.problem_mark or e.context_mark
        problem = f"{e.problem or e}"
        problem += _character_at(text, mark, named="found character '" in problem)
        msg = f"YAML syntax error: {problem}" + (f" ({e.context})" if e.context else "")
        raise InputFileError([InputIssue(name, _line_in(text, mark), "", msg)]) from e
    except UnicodeError as e:  # libyaml's parser takes UTF-8: a lone surrogate cannot be
        msg = f"not valid Unicode text ({e})"
        raise InputFileError([InputIssue(name, None, "", msg)]) from None
    except yaml.YAMLError as e:
        raise InputFileError([InputIssue(name, None, "", f"YAML error: {e}")]) from e
    except RecursionError:  # not expected past the depth check; a message all the same
        msg = "nested too deeply to read"
        raise InputFileError([InputIssue(name, None, "", msg)]) from None


def _line_in(text: str, mark: Any) -> int | None:
    """The 1-based line of ``mark``, at most the text's last line (libyaml names the line
    after the last when an error is found at the end of a text without a final newline)."""
    line = _line(mark)
    if line is None:
        return None
    last = text.count("\n") + (0 if text.endswith("\n") else 1)
    return max(1, min(line, last))


def _character_at(text: str, mark: Any, named: bool) -> str:
    """`` ('@')``: the character a syntax error found, which libyaml's message leaves out
    (PyYAML's parser in Python names it: ``named``); for a tab, what to write instead."""
    if mark is None:
        return ""
    lines = text.splitlines()
    if not 0 <= mark.line < len(lines) or not 0 <= mark.column < len(lines[mark.line]):
        return ""
    char = lines[mark.line][mark.column]
    if char == "\t":
        return " (a tab: YAML indents and separates with spaces)"
    return f" ({char!r})" if not (named or char.isspace()) else ""


def what_was_given(value: object) -> str:
    """`` (got ...)`` for a refused value in a message: its repr when short, a date as YAML
    read it (``2026-01-01`` unquoted is a date, not text); empty for a long value."""
    if isinstance(value, datetime.date):
        return f" (got {value.isoformat()}, which YAML reads as a date: quote it if it is text)"
    shown = repr(value)
    return f" (got {shown})" if len(shown) < 60 else ""


def issues_from_validation(name: str, err: ValidationError, lines: dict) -> list[InputIssue]:
    """Turn pydantic errors into file:line issues with a readable field path."""
    issues = []
    for e in err.errors():
        loc = tuple(x for x in e["loc"] if not (isinstance(x, str) and x.startswith("function-")))
        field = ".".join(str(x) if isinstance(x, str) else f"[{x}]" for x in loc).replace(".[", "[")
        msg = e["msg"]
        if e["type"] == "extra_forbidden":
            msg = "unknown key (not part of the schema; check the spelling)"
        elif e["type"] == "missing":
            msg = "required key is missing"
        if "input" in e and e["type"] not in ("missing", "extra_forbidden"):
            msg += what_was_given(e["input"])
        issues.append(InputIssue(name, _line_for(loc, lines), field, msg))
    return issues


def load_model(path: Path | str, model: type[M], context: dict | None = None) -> M:
    """Read ``path`` and validate it as ``model``; raise :class:`InputFileError` on any problem."""
    data, lines, _ = read_yaml(path)
    name = str(path)
    if data is None:
        raise InputFileError([InputIssue(name, 1, "", "file is empty; expected a YAML mapping")])
    if not isinstance(data, dict):
        msg = f"expected a YAML mapping (key: value) at the top, got {type(data).__name__}"
        raise InputFileError([InputIssue(name, 1, "", msg)])
    try:
        return model.model_validate(data, context=context)
    except ValidationError as e:
        raise InputFileError(issues_from_validation(name, e, lines)) from e
