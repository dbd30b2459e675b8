"""Design-document citations in the code resolve inside the repository.

Oracle: the numbered headings of ``docs/*.md`` (docs/README.md excepted). A heading line of one or more ``#``
whose first word is a section number - digits with dots (``## 6. ...``, ``### 6.2 ...``) or a capital letter
with optional dotted digits (``## C. ...``, ``### C.<n> ...``) - defines that section in that document.

Checked in every ``*.py`` under tpnet_gpu/, kernels/, net/, bench/ and tests/:

* explicit citations: a document name ending in ``.md`` followed by a list of section numbers (paragraph sign
  and digits, or letter sections), separated by commas, slashes or "and", with ranges written with a dash.
  The document must exist as docs/<name> and have a heading for every number (and every number inside a
  range).
* bare citations: a section number with no document name in front (also "spec ..." or "geometry ...").
  Among the documents the file's module docstring names, exactly one must have that heading; a file whose
  docstring names none needs exactly one document in docs/ with it.

Standard library and pytest only; nothing from the project is imported.
"""

from __future__ import annotations

import ast
import re
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"
SCANNED = ("tpnet_gpu", "kernels", "net", "bench", "tests")

# Citations known to be unresolved in files this branch may not edit, as (path, citation text). Empty by
# design: a new entry needs a reason next to it, and the doc headings should rather be made to cover it.
KNOWN_LEFTOVERS: frozenset[tuple[str, str]] = frozenset()

PARA = "\u00a7"  # the section sign
_HEADING = re.compile(r"^#{1,6}[ \t]+(\d+(?:\.\d+)*|[A-Z](?:\.\d+)+|[A-Z](?=\.))\.?(?=[ \t]|$)", re.M)
_NUM = rf"{PARA}[ \t]?\d+(?:\.\d+)*"  # paragraph-sign section
_LETTER = r"[A-Z](?:\.\d+)*"  # letter section (a lone letter only inside an explicit list)
_LETTER_BARE = r"(?<![\w.])[A-Z]\.\d+(?:\.\d+)*(?![\w])"  # a letter section on its own needs a number
_RANGE_END = rf"(?:{PARA}[ \t]?)?\d+(?:\.\d+)*|[A-Z]\.\d+(?:\.\d+)*"
_RANGE = rf"[ \t]*[-\u2013][ \t]*(?:{_RANGE_END})"
# A letter item must end a word: followed by a range, a separator, a closing bracket or the end of the line.
_ITEM = rf"(?:{_NUM}(?:{_RANGE})?|{_LETTER}{_RANGE}|{_LETTER}(?=[\s,;:)/]|$))"
_SEP = r"[ \t]*(?:,|/|\band\b)[ \t]*"
_EXPLICIT = re.compile(rf"\b([A-Za-z][\w-]*\.md)\b[\s#]*((?:{_ITEM})(?:{_SEP}(?:{_ITEM}))*)")
_ITEM_PARTS = re.compile(
    rf"({PARA}[ \t]?\d+(?:\.\d+)*|[A-Z](?:\.\d+)*)(?:[ \t]*[-\u2013][ \t]*({_RANGE_END}))?")
_BARE = re.compile(rf"({_NUM}|{_LETTER_BARE})(?:[ \t]*[-\u2013][ \t]*({_RANGE_END}))?")
_DOC_NAME = re.compile(r"\b([A-Za-z][\w-]*\.md)\b")


@dataclass(frozen=True)
class Citation:
    path: str  # relative to the repository root
    line: int
    text: str  # as written: a document and its section list, or a bare section or range
    doc: str | None  # "network.md", or None for a bare citation
    sections: tuple[str, ...]  # section numbers without the paragraph sign, ranges expanded

    def where(self) -> str:
        return f"{self.path}:{self.line}: {self.text!r}"


def doc_sections(docs_dir: Path = DOCS) -> dict[str, set[str]]:
    """Section numbers per document name, from the headings of ``docs_dir/*.md`` (README.md excepted)."""
    out = {}
    for path in sorted(docs_dir.glob("*.md")):
        if path.name != "README.md":
            out[path.name] = set(_HEADING.findall(path.read_text(encoding="utf-8")))
    return out


def _number(token: str) -> str:
    return token.replace(PARA, "").strip()


def _expand(first: str, last: str | None) -> tuple[str, ...]:
    """A section or a range of them; a range ("1" to "4", or a letter section "<L>.1" to "<L>.3") includes every
    number in between."""
    first = _number(first)
    if last is None:
        return (first,)
    last = _number(last)
    head_a, _, tail_a = first.rpartition(".")
    head_b, _, tail_b = last.rpartition(".")
    if head_a == head_b and tail_a.isdigit() and tail_b.isdigit() and int(tail_a) < int(tail_b):
        prefix = head_a + "." if head_a else ""
        return tuple(f"{prefix}{i}" for i in range(int(tail_a), int(tail_b) + 1))
    return (first, last)


def _line_of(text: str, offset: int) -> int:
    return text.count("\n", 0, offset) + 1


def find_citations(text: str, path: str = "<text>") -> list[Citation]:
    """Every explicit and bare citation in ``text`` (a Python source file)."""
    found, taken = [], []
    for match in _EXPLICIT.finditer(text):
        doc, items = match.group(1), match.group(2)
        sections = []
        for item in _ITEM_PARTS.finditer(items):
            sections.extend(_expand(item.group(1), item.group(2)))
        found.append(Citation(path, _line_of(text, match.start()), match.group(0).strip(), doc, tuple(sections)))
        taken.append(match.span(2))
    for match in _BARE.finditer(text):
        if any(a <= match.start() < b for a, b in taken):
            continue
        found.append(Citation(path, _line_of(text, match.start()), match.group(0).strip(), None,
                              _expand(match.group(1), match.group(2))))
    return sorted(found, key=lambda c: c.line)


def docstring_docs(text: str) -> set[str]:
    """Document names (``*.md``) the module docstring of ``text`` mentions."""
    doc = ast.get_docstring(ast.parse(text)) or ""
    return set(_DOC_NAME.findall(doc))


def problems(citation: Citation, named: set[str], sections: dict[str, set[str]]) -> list[str]:
    """Why ``citation`` does not resolve (empty when it does)."""
    out = []
    if citation.doc is not None:
        if citation.doc not in sections:
            return [f"{citation.where()}: docs/{citation.doc} does not exist (docs/: {sorted(sections)})"]
        for number in citation.sections:
            if number not in sections[citation.doc]:
                out.append(f"{citation.where()}: docs/{citation.doc} has no heading numbered {number}")
        return out
    named = named & set(sections)  # design documents only (a mention of README.md names no sections)
    candidates = sorted(named) if named else sorted(sections)
    scope = f"the docs its module docstring names {sorted(named)}" if named else "docs/ (its docstring names none)"
    for number in citation.sections:
        holders = [d for d in candidates if number in sections[d]]
        if len(holders) != 1:
            what = "none" if not holders else "more than one: " + ", ".join(holders)
            out.append(f"{citation.where()}: bare section {number} must be a heading of exactly one of {scope}; "
                       f"found {what} - name the document")
    return out


def scanned_files(root: Path = ROOT) -> list[Path]:
    return sorted(p for top in SCANNED for p in (root / top).rglob("*.py"))


def check_tree(root: Path = ROOT, docs_dir: Path = DOCS) -> tuple[list[Citation], list[str]]:
    """All citations under ``root`` and the problems of those not in ``KNOWN_LEFTOVERS``."""
    sections = doc_sections(docs_dir)
    citations, failures = [], []
    for path in scanned_files(root):
        text = path.read_text(encoding="utf-8")
        rel = path.relative_to(root).as_posix()
        named = docstring_docs(text)
        for citation in find_citations(text, rel):
            citations.append(citation)
            if (rel, citation.text) not in KNOWN_LEFTOVERS:
                failures.extend(problems(citation, named, sections))
    return citations, failures


# --- tests ------------------------------------------------------------------------------------------------
def test_every_citation_resolves_to_a_doc_heading():
    citations, failures = check_tree()
    print(f"{len(citations)} citations checked in {len(scanned_files())} files against the headings of "
          f"{sorted(doc_sections())}")
    assert not failures, "unresolved design-document citations:\n" + "\n".join(failures)


def test_the_scan_finds_the_citations():
    # Guards the scanner itself: the code cites the design documents in well over a hundred places.
    citations, _ = check_tree()
    assert len(citations) >= 150, f"only {len(citations)} citations found: is the citation pattern broken?"
    assert {c.doc for c in citations if c.doc} >= {"tile_processor.md", "network.md", "geometry_and_lma.md"}


def test_known_leftovers_are_still_there():
    citations, _ = check_tree()
    present = {(c.path, c.text) for c in citations}
    stale = sorted(KNOWN_LEFTOVERS - present)
    assert not stale, f"KNOWN_LEFTOVERS entries no longer in the code (remove them): {stale}"


def test_each_doc_numbers_its_sections_once():
    for path in sorted(DOCS.glob("*.md")):
        if path.name == "README.md":
            continue
        numbers = _HEADING.findall(path.read_text(encoding="utf-8"))
        repeated = sorted({n for n in numbers if numbers.count(n) > 1})
        assert numbers, f"docs/{path.name}: no numbered headings"
        assert not repeated, f"docs/{path.name}: section numbers used by more than one heading: {repeated}"


def test_docs_index_lists_every_document():
    index = (DOCS / "README.md").read_text(encoding="utf-8")
    missing = [name for name in doc_sections() if name not in index]
    assert not missing, f"docs/README.md does not list {missing}"


def test_parser_on_known_forms():
    # Oracle: citations written out by hand, one of each form the code uses ("$" stands for the paragraph
    # sign and "@" for the dot of a letter section, so that this file does not cite anything itself).
    sample = (
        '"""Module (alpha.md $1.4, $3-$5; beta.md B@3\u2013B@5, D)."""\n'
        "x = 1  # bare $2 and spec C@4, geometry A@2/A@6 and $1-3\n"
    ).replace("$", PARA).replace("@", ".")
    got = [(c.line, c.doc, c.sections) for c in find_citations(sample)]
    expected = [
        (1, "alpha.md", "1.4 3 4 5"),
        (1, "beta.md", "B@3 B@4 B@5 D"),
        (2, None, "2"),
        (2, None, "C@4"),
        (2, None, "A@2"),
        (2, None, "A@6"),
        (2, None, "1 2 3"),
    ]
    assert got == [(line, doc, tuple(numbers.replace("@", ".").split())) for line, doc, numbers in expected]
    sections = {"alpha.md": {"1.4", "2", "3", "4", "5"}, "beta.md": {"A@2", "B@3", "B@4", "B@5", "D"}}
    sections = {doc: {n.replace("@", ".") for n in numbers} for doc, numbers in sections.items()}
    named = docstring_docs(sample)
    assert named == {"alpha.md", "beta.md"}
    bad = [p for c in find_citations(sample) for p in problems(c, named, sections)]
    assert len(bad) == 3 and all("name the document" in p for p in bad)  # C@4, A@6 and 1 exist nowhere
    missing_doc = Citation("x.py", 1, "gamma.md", "gamma.md", ("1",))
    assert "does not exist" in problems(missing_doc, set(), sections)[0]
    both = {"alpha.md": {"2"}, "beta.md": {"2"}}  # a bare number two named documents share is ambiguous
    assert "more than one" in problems(Citation("x.py", 1, "2", None, ("2",)), set(both), both)[0]
    assert "more than one" in problems(Citation("x.py", 1, "2", None, ("2",)), set(), both)[0]
    assert not problems(Citation("x.py", 1, "2", None, ("2",)), {"alpha.md"}, both)
