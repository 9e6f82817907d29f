"""Every config key with its default, type, allowed values and doc, for ``roshan config show [SECTION]``.

The doc is the field's ``doc=`` (``num``/``choice``), else the comment on its line in the section's source."""

import ast
import dataclasses
import difflib
import functools
import inspect
import io
import textwrap
import tokenize
import types
import typing

from roshan.config.schema import ALIASES, ConfigError


@functools.cache
def _line_comments(cls: type) -> dict[str, str]:
    """``{field: comment}`` of a section class's ``name: type = value  # comment`` lines."""
    try:
        source = textwrap.dedent(inspect.getsource(cls))
    except (OSError, TypeError):  # no source (a frozen or generated class): no comments
        return {}
    comments: dict[int, str] = {}
    for tok in tokenize.generate_tokens(io.StringIO(source).readline):
        if tok.type == tokenize.COMMENT:
            comments[tok.start[0]] = tok.string.lstrip("#").strip()
    (node,) = [n for n in ast.parse(source).body if isinstance(n, ast.ClassDef)]
    out = {}
    for stmt in node.body:
        if isinstance(stmt, ast.AnnAssign) and isinstance(stmt.target, ast.Name):
            found = [comments[n] for n in range(stmt.lineno, stmt.end_lineno + 1) if n in comments]
            if found:
                out[stmt.target.id] = " ".join(found)
    return out


def _type_name(hint) -> str:
    if typing.get_origin(hint) in (typing.Union, types.UnionType):
        return " | ".join("None" if a is type(None) else a.__name__ for a in typing.get_args(hint))
    return getattr(hint, "__name__", str(hint))


def _value_text(value) -> str:
    """A default as it is written in YAML or ``--set``."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if value is None:
        return "null"
    if value == "":
        return '""'
    return str(value)


def _allowed_text(meta, hint) -> str:
    if hint is bool:
        return "true | false"
    if not meta:
        return ""
    if meta.get("choices") is not None:
        return " | ".join(_value_text(c) for c in meta["choices"])
    lo, hi = meta.get("lo"), meta.get("hi")
    if lo is None and hi is None:
        return ""
    if hi is None:
        return f"{'>' if meta['lo_open'] else '>='} {lo}"
    if lo is None:
        return f"{'<' if meta['hi_open'] else '<='} {hi}"
    return f"{'(' if meta['lo_open'] else '['}{lo}, {hi}{')' if meta['hi_open'] else ']'}"


def sections(cls: type, prefix: str = "") -> list[tuple[str, type]]:
    """``(dotted name, class)`` of every section under ``cls`` in tree order (the root is ``""``)."""
    out = [(prefix.rstrip("."), cls)]
    for f in dataclasses.fields(cls):
        hint = typing.get_type_hints(cls)[f.name]
        if dataclasses.is_dataclass(hint):
            out += sections(hint, f"{prefix}{f.name}.")
    return out


def describe_keys(cls: type, section: str = "") -> list[dict]:
    """One dict per key (``key, type, default, allowed, doc, section``) of the tree ``cls``, limited to the
    section ``section`` (``fire``, ``planner.rewards``) or to one key (``fire.dt``); "" is every key.

    Raises:
        ConfigError: for an unknown section or key, with the closest name.
    """
    rows = []
    for name, sec in sections(cls):
        hints = typing.get_type_hints(sec)
        comments = _line_comments(sec)
        for f in dataclasses.fields(sec):
            hint = hints[f.name]
            if dataclasses.is_dataclass(hint):
                continue
            default = f.default if f.default is not dataclasses.MISSING else f.default_factory()
            rows.append({"key": f"{name}.{f.name}" if name else f.name, "section": name, "type": _type_name(hint),
                         "default": _value_text(default), "allowed": _allowed_text(f.metadata, hint),
                         "doc": (f.metadata or {}).get("doc") or comments.get(f.name, "")})
    if not section:
        return rows
    picked = [r for r in rows if r["key"] == section or r["key"].startswith(section + ".")]
    if not picked:
        names = [n for n, _ in sections(cls) if n]
        raise ConfigError(f"unknown config section {section!r}{_closest(section, names, [r['key'] for r in rows])}")
    return picked


def _closest(name: str, section_names: list[str], keys: list[str]) -> str:
    """"; did you mean 'x'?" for a section or key that is plausibly what ``name`` misspells, else what there is
    to choose from: a name inside a known section (``fire.dtt``) is matched against that section's keys and
    subsections (or they are listed), any other against the section names (or those are listed). A word that
    resembles nothing ("nosuchsection") gets the list, never a far-off key."""
    head, _, last = name.rpartition(".")
    if head in section_names:
        children = {n.rpartition(".")[2]: n for n in section_names + keys if n.rpartition(".")[0] == head}
        alias = ALIASES.get(last)
        close = [alias] if alias in children else difflib.get_close_matches(last, list(children), n=1, cutoff=0.6)
        if close:
            return f"; did you mean {children[close[0]]!r}?"
        return f"; {head} has: {', '.join(children)}"
    close = difflib.get_close_matches(name, section_names, n=1, cutoff=0.6)
    if not close:
        close = difflib.get_close_matches(name, keys, n=1, cutoff=0.8)
    return f"; did you mean {close[0]!r}?" if close else f"; sections: {', '.join(section_names)}"


def format_keys(cls: type, rows: list[dict]) -> str:
    """The rows as aligned columns under one heading per section (its name and docstring)."""
    docs = {name: " ".join((inspect.getdoc(sec) or "").split("\n\n")[0].split()) for name, sec in sections(cls)}
    widths = {c: max(len(c), *(len(r[c]) for r in rows)) for c in ("key", "type", "default", "allowed")}
    line = "  ".join(f"{{{c}:<{w}}}" for c, w in widths.items()) + "  {doc}"
    out, current = [line.format(key="key", type="type", default="default", allowed="allowed", doc="doc")], None
    for r in rows:
        if r["section"] != current:
            current = r["section"]
            out += ["", f"{current or 'top level'}: {docs.get(current, '')}".rstrip()]
        out.append(line.format(**r).rstrip())
    return "\n".join(out)
