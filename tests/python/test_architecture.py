"""Every source file has a test (issue 27 item 8): a test file of its own, mirrored
(csrc/<area>/<name>.{h,cpp} -> tests/cpp/<area>/test_<name>.cpp; python/flagsim/[<pkg>/]<name>.py
-> tests/python/test_[<pkg>_]<name>.py), or a row in docs/architecture.md ("Every source file and
its test") naming existing tests that cover it. A new source file without either fails here, and
so does a row that names a test file that is not there. `none` is accepted only for a file that
holds no code (a docstring, imports)."""

import ast
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
DOC = ROOT / "docs" / "architecture.md"
# docs/architecture.md's sections of the source table, and the folder each one's paths are in
SECTIONS = {"csrc/": "csrc", "python/flagsim/": "python/flagsim", "benchmarks/": "benchmarks"}
SOURCE_SUFFIXES = {".h", ".cpp", ".py", ".in"}
# Test files named in a row: full paths, or a bare name in the folder of the last full one.
FULL_TEST = re.compile(r"\b((?:tests/(?:cpp|python)|examples/cpp)/[\w/]+\.(?:cpp|py))\b")
BARE_TEST = re.compile(r"(?<![\w/])(test_\w+\.(?:cpp|py))\b")


def source_files() -> list[Path]:
    files = []
    for folder in SECTIONS.values():
        for p in sorted((ROOT / folder).rglob("*")):
            if p.is_file() and p.suffix in SOURCE_SUFFIXES and "__pycache__" not in p.parts:
                files.append(p.relative_to(ROOT))
    return files


def own_test(path: Path) -> Path | None:
    """The mirrored test file of a source file, if it exists."""
    parts = path.parts
    if parts[0] == "csrc":
        candidates = [Path("tests/cpp", *parts[1:-1], f"test_{path.stem}.cpp")]
    elif parts[:2] == ("python", "flagsim"):
        pkg = "_".join(parts[2:-1])
        candidates = [Path("tests/python", f"test_{path.stem}.py")]
        if pkg:
            candidates.insert(0, Path("tests/python", f"test_{pkg}_{path.stem}.py"))
    else:
        candidates = []
    return next((c for c in candidates if (ROOT / c).is_file()), None)


def documented_rows() -> dict[str, str]:
    """{source path (a folder's ending in /): its test cell} from docs/architecture.md."""
    rows: dict[str, str] = {}
    folder = None
    for line in DOC.read_text(encoding="utf-8").splitlines():
        heading = re.match(r"### (\S+)", line)
        if heading:
            folder = SECTIONS.get(heading.group(1))
            continue
        if folder is None or not line.startswith("| ") or line.startswith("| file |"):
            continue
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) != 3:
            continue
        names = cells[0].replace("\\_", "_").split(", ")
        first = Path(names[0])
        for name in names:
            if name.startswith("."):  # "keyframes.h, .cpp"
                p = first.with_suffix(name)
            elif "/" not in name and name != names[0]:  # "flag.pov.in, flag.ini.in"
                p = first.parent / name
            else:
                p = Path(name)
            rows[str(Path(folder) / p) + ("/" if name.endswith("/") else "")] = cells[2]
    return rows


def named_tests(cell: str) -> list[Path]:
    found: list[Path] = []
    last_dir = None
    for m in re.finditer(f"{FULL_TEST.pattern}|{BARE_TEST.pattern}", cell):
        if m.group(1):
            p = Path(m.group(1))
            last_dir = p.parent
        elif last_dir is not None:
            p = last_dir / m.group(2)
        else:
            p = Path(m.group(2))
        found.append(p)
    return found


def holds_no_code(path: Path) -> bool:
    if path.suffix != ".py":
        return False
    body = ast.parse((ROOT / path).read_text(encoding="utf-8")).body
    return all(
        isinstance(n, (ast.Import, ast.ImportFrom))
        or (isinstance(n, ast.Expr) and isinstance(n.value, ast.Constant))
        for n in body
    )


def row_for(path: Path, rows: dict[str, str]) -> str | None:
    if str(path) in rows:
        return rows[str(path)]
    for key, cell in rows.items():  # a folder row ("bindings/")
        if key.endswith("/") and str(path).startswith(key):
            return cell
    return None


def coverage() -> list[tuple[Path, str, str]]:
    """(source file, how it is covered or "", what is wrong or "") for every source file."""
    rows = documented_rows()
    out = []
    for path in source_files():
        own = own_test(path)
        cell = row_for(path, rows)
        if cell is None:
            out.append((path, str(own or ""), "" if own else "no test file and no row"))
            continue
        tests = named_tests(cell)
        missing = [str(t) for t in tests if not (ROOT / t).is_file()]
        if missing:
            out.append((path, cell, f"the row names missing tests: {', '.join(missing)}"))
        elif own or tests or "every Python test" in cell:
            out.append((path, str(own or cell), ""))
        elif holds_no_code(path):
            out.append((path, "no code", ""))
        else:
            out.append((path, cell, f"the row names no test: {cell!r}"))
    return out


def test_the_doc_rows_are_read():
    # the parser sees the table (a reformatted page must not make the check vacuous)
    rows = documented_rows()
    assert "csrc/common/keyframes.cpp" in rows and "csrc/common/keyframes.h" in rows
    assert "csrc/bindings/" in rows and "python/flagsim/__init__.py" in rows
    assert "python/flagsim/povray/templates/flag.ini.in" in rows
    assert "benchmarks/report.py" in rows
    assert named_tests("tests/cpp/scene/test_simulation.cpp, test_energy_ledger.cpp") == [
        Path("tests/cpp/scene/test_simulation.cpp"),
        Path("tests/cpp/scene/test_energy_ledger.cpp"),
    ]
    assert own_test(Path("python/flagsim/povray/mesh.py")) == Path(
        "tests/python/test_povray_mesh.py"
    )
    assert own_test(Path("csrc/fluid/advect.cpp")) == Path("tests/cpp/fluid/test_advect.cpp")


def test_every_source_file_has_a_test():
    problems = [f"{p}: {why}" for p, _, why in coverage() if why]
    assert not problems, "\n".join(problems)
