"""What an installed copy holds: pyproject.toml's hand-written lists of packages and data files against the tree, so
that a new subpackage or template folder cannot drop out of the wheel while the checkout's tests, which read the
tree, still pass."""

from __future__ import annotations

import fnmatch
from pathlib import Path

from fitgen.base.texts import tomllib

ROOT = Path(__file__).resolve().parents[1]
TOP = ("fitgen", "host", "hil", "firmware_templates")


def _config():
    return tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]


def _tree_files():
    for top in TOP:
        for path in sorted((ROOT / top).rglob("*")):
            if path.is_file() and "__pycache__" not in path.parts and path.suffix not in (".pyc", ".pyo"):
                yield path.relative_to(ROOT)


def test_every_folder_with_modules_is_a_listed_package():
    listed = set(_config()["packages"])
    folders = {".".join(p.parent.parts) for p in _tree_files() if p.suffix == ".py"}
    assert folders - listed == set(), "pyproject.toml's [tool.setuptools] packages lacks these"
    assert listed - folders == set(), "pyproject.toml lists packages the tree does not have"


def test_every_data_file_matches_its_package_s_package_data():
    """Each file that is not a module, under the package that holds it (the nearest listed one up the tree), is
    matched by one of that package's globs, as setuptools matches them (relative to the package's folder)."""
    cfg = _config()
    listed, data = set(cfg["packages"]), cfg["package-data"]
    missing = []
    for path in _tree_files():
        if path.suffix == ".py":
            continue
        owner = next(".".join(path.parts[:n]) for n in range(len(path.parts) - 1, 0, -1)
                     if ".".join(path.parts[:n]) in listed)
        inside = Path(*path.parts[len(owner.split(".")):]).as_posix()
        if not any(fnmatch.fnmatchcase(inside, glob) and inside.count("/") == glob.count("/")
                   for glob in data.get(owner, [])):
            missing.append(str(path))
    assert missing == [], "not in any package-data glob of pyproject.toml: left out of the wheel"


def test_the_source_distribution_takes_the_tests_with_their_helpers_and_data():
    """An sdist whose tests lack conftest.py and tests/data cannot run them: MANIFEST.in grafts the folders."""
    lines = [ln.split() for ln in (ROOT / "MANIFEST.in").read_text().splitlines() if ln and not ln.startswith("#")]
    grafted = {words[1] for words in lines if words[0] == "graft"}
    assert {"tests", "docs", "scripts"} <= grafted
    assert (ROOT / "tests" / "conftest.py").is_file() and (ROOT / "tests" / "data").is_dir()
    assert ["include", "LICENSE", "README.md"] in lines and (ROOT / "LICENSE").is_file()


def test_the_set_up_takes_a_python3_with_pip_and_makes_a_venv_for_one_without(tmp_path):
    """scripts/python.sh (both README commands source it): a python3 that pip may install into is used as it is;
    one without pip (as the system's of a fresh Debian, or one PEP 668 closes) gets .venv in the checkout, made
    once, with pip."""
    import shutil
    import subprocess
    import sys

    checkout = tmp_path / "checkout"
    (checkout / "scripts").mkdir(parents=True)
    shutil.copy(ROOT / "scripts" / "python.sh", checkout / "scripts")
    say = '. scripts/python.sh && echo "$PY" && "$PY" -m pip --version'

    def set_up(python_bin):
        return subprocess.run(["bash", "-c", say], cwd=checkout, capture_output=True, text=True, timeout=300,
                              env={"PATH": f"{python_bin}:/usr/bin:/bin", "HOME": str(tmp_path)})

    bare = tmp_path / "nopip"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(bare)], check=True, timeout=300)
    proc = set_up(bare / "bin")
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.splitlines()[0] == str(checkout / ".venv" / "bin" / "python")
    assert proc.stdout.splitlines()[1].startswith("pip ") and "making a virtual environment" in proc.stderr
    again = set_up(bare / "bin")  # made once: the second run takes it without a word
    assert again.returncode == 0 and again.stdout == proc.stdout and again.stderr == ""
    subprocess.run([str(checkout / ".venv" / "bin" / "python"), "-m", "pip", "uninstall", "-y", "-q", "pip"],
                   check=True, timeout=300)  # as a run stopped half-way leaves it: made anew, not taken
    mended = set_up(bare / "bin")
    assert mended.returncode == 0 and mended.stdout == proc.stdout, mended.stderr
    shutil.rmtree(checkout / ".venv")
    with_pip = tmp_path / "withpip"  # a Python pip may install into: taken as it is
    subprocess.run([sys.executable, "-m", "venv", str(with_pip)], check=True, timeout=300)
    own = set_up(with_pip / "bin")
    assert own.returncode == 0 and own.stdout.splitlines()[0] == "python3", own.stderr
    assert not (checkout / ".venv").exists()


def test_every_bench_script_imports():
    """A bench whose import broke goes unseen until someone runs it (bench/layouts.py and bench/hil_speed.py
    imported tomllib from where a refactor had taken it away): each is imported, its main left unrun."""
    import subprocess
    import sys

    bench = Path(__file__).resolve().parent.parent / "bench"
    code = ("import importlib, pathlib, sys\nsys.path.insert(0, sys.argv[1])\nbad = []\n"
            "for p in sorted(pathlib.Path(sys.argv[1]).glob('*.py')):\n"
            "    try:\n        importlib.import_module(p.stem)\n"
            "    except Exception as exc:\n        bad.append(f'{p.name}: {exc!r}')\nprint('\\n'.join(bad))\n")
    proc = subprocess.run([sys.executable, "-c", code, str(bench)], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0 and proc.stdout.strip() == "", proc.stdout + proc.stderr
    assert len(list(bench.glob("*.py"))) > 30  # the folder is there, with its scripts
