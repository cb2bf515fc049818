"""No module of ours reaches into the mcap library's private attributes, read from the code with ``ast``.

A private attribute (``writer._Writer__chunk_indices``) is no contract: a patch release may rename
it, and code that patches it breaks silently (mcap 1.x's chunk-index list was once replaced this way;
``executive.mcap_file`` now writes the file from mcap's public records instead). Three shapes are
refused in planner/, executive/ and vehicle_sim/:

- a name-mangled name (``_Class__name``) anywhere, as an attribute or a string;
- ``x._name``, or ``getattr``/``setattr``/``hasattr``/``delattr`` of ``x`` with a private name
  (``"_x"``) as a constant, where ``x`` was made by a call to something imported from ``mcap``, or
  is annotated with a type imported from it.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
PACKAGES = ("planner", "executive", "vehicle_sim")
LIBRARY = "mcap"
_MANGLED = re.compile(r"^_[A-Za-z]\w*?__\w+$")
_MANGLED_IN_TEXT = re.compile(r"\b_[A-Za-z]\w*?__\w")
_REFLECTION = frozenset({"getattr", "setattr", "hasattr", "delattr"})


def _private(name: str) -> bool:
    return name.startswith("_") and not (name.startswith("__") and name.endswith("__"))


def _library_names(tree: ast.AST) -> set[str]:
    """Names a module binds to the library: ``import mcap``, ``from mcap.writer import Writer``."""
    names: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names |= {(a.asname or a.name).split(".")[0] for a in node.names if a.name.split(".")[0] == LIBRARY}
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and (node.module or "").split(".")[0] == LIBRARY:
            names |= {a.asname or a.name for a in node.names}
    return names


def _root(node: ast.AST) -> str | None:
    while isinstance(node, ast.Attribute | ast.Call | ast.Subscript):
        node = node.func if isinstance(node, ast.Call) else node.value
    return node.id if isinstance(node, ast.Name) else None


def _library_objects(tree: ast.AST, library: set[str]) -> set[str]:
    """Source text of what holds a library object: ``writer``, ``self._writer``."""
    held: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Assign | ast.AnnAssign) and isinstance(node.value, ast.Call):
            if _root(node.value) in library:
                targets = node.targets if isinstance(node, ast.Assign) else [node.target]
                held |= {ast.unparse(t) for t in targets}
        elif isinstance(node, ast.withitem) and isinstance(node.context_expr, ast.Call):
            if _root(node.context_expr) in library and node.optional_vars is not None:
                held.add(ast.unparse(node.optional_vars))
        if isinstance(node, ast.arg | ast.AnnAssign) and node.annotation is not None:
            annotated = {_root(n) for n in ast.walk(node.annotation)}
            if annotated & library:
                held.add(node.arg if isinstance(node, ast.arg) else ast.unparse(node.target))
    return held


def violations(source: str, where: str) -> list[str]:
    tree = ast.parse(source)
    library = _library_names(tree)
    held = _library_objects(tree, library)
    found: list[str] = []
    for node in ast.walk(tree):
        line = f"{where}:{getattr(node, 'lineno', '?')}"
        if isinstance(node, ast.Attribute) and _MANGLED.match(node.attr):
            found.append(f"{line}: name-mangled attribute {node.attr}")
        elif isinstance(node, ast.Constant) and isinstance(node.value, str) and _MANGLED.match(node.value):
            found.append(f"{line}: name-mangled name {node.value!r}")
        elif not held:
            continue
        elif (isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id in _REFLECTION
              and len(node.args) >= 2 and isinstance(node.args[1], ast.Constant)
              and isinstance(node.args[1].value, str) and _private(node.args[1].value)
              and ast.unparse(node.args[0]) in held):
            found.append(f"{line}: {node.func.id}({ast.unparse(node.args[0])}, {node.args[1].value!r})")
        elif isinstance(node, ast.Attribute) and _private(node.attr) and ast.unparse(node.value) in held:
            found.append(f"{line}: {ast.unparse(node)}: a private attribute of an {LIBRARY} object")
    return found


def test_no_module_of_ours_touches_a_private_attribute_of_an_mcap_object():
    found: list[str] = []
    for path in sorted(p for pkg in PACKAGES for p in (REPO / pkg).rglob("*.py")):
        text = path.read_text()
        if LIBRARY in text or _MANGLED_IN_TEXT.search(text):  # only these can break a rule: parse them
            found += violations(text, str(path.relative_to(REPO)))
    assert found == []


def test_the_scan_finds_each_shape():
    """The check above can fail: the old chunk-index patch and its variants are found."""
    old = '''
from mcap.writer import Writer
from mcap.reader import make_reader

def spool_chunk_indexes(writer, directory):
    name = "_Writer__chunk_indices"
    setattr(writer, name, ChunkIndexSpool(directory))

class Recorder:
    def __init__(self, f):
        self._writer = Writer(f)
        self._writer._Writer__chunk_indices = []
        print(getattr(self._writer, "_chunk_builder", None))
        self._own = 1

def summary(f, w: Writer):
    reader = make_reader(f)
    with make_reader(f) as r:
        r._stream.seek(0)
    w._statistics.chunk_count = 0
    return reader._summary, self._own, w.__class__
'''
    found = {v.split(": ", 1)[1] for v in violations(old, "old.py")}
    assert found == {
        "name-mangled name '_Writer__chunk_indices'",
        "name-mangled attribute _Writer__chunk_indices",
        "getattr(self._writer, '_chunk_builder')",
        "r._stream: a private attribute of an mcap object",
        "w._statistics: a private attribute of an mcap object",
        "reader._summary: a private attribute of an mcap object",
    }  # and not self._own: our own object's attribute
