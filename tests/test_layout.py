"""The package's shape: one installable top-level name (``neuralao``), whose subpackages are the layer
folders at the root, every module imported by its one ``neuralao.`` path, loggers named after their
modules, and the build and import-linter configuration naming every package and runtime module."""

from __future__ import annotations

import ast
import shutil
import subprocess
import sys
import tomllib
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
LAYERS = ("pipeline", "export", "runtime")
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())


def _python_files() -> list[Path]:
    files = [p for layer in LAYERS for p in (ROOT / layer).rglob("*.py")]
    return files + sorted((ROOT / "tests").glob("*.py")) + sorted((ROOT / "bench").glob("*.py"))


def _package_folders() -> set[str]:
    return {
        "neuralao." + ".".join(init.parent.relative_to(ROOT).parts)
        for layer in LAYERS
        for init in (ROOT / layer).rglob("__init__.py")
        if "__pycache__" not in init.parts
    }


def test_build_configuration_lists_every_package_folder():
    listed = set(PYPROJECT["tool"]["setuptools"]["packages"])
    assert listed == _package_folders()
    assert PYPROJECT["tool"]["setuptools"]["package-dir"] == {"neuralao": "."}


def test_layers_contract_names_every_runtime_module():
    layers = PYPROJECT["tool"]["importlinter"]["contracts"][0]["layers"]
    named = {m.strip(" ()") for layer in layers for m in layer.replace("|", ":").split(":")}
    runtime = {f"neuralao.runtime.{p.stem}" for p in (ROOT / "runtime").glob("*.py") if p.stem != "__init__"}
    runtime |= {f"neuralao.runtime.{p.parent.name}" for p in (ROOT / "runtime").glob("*/__init__.py")}
    assert runtime - named == set()


def _imports(path: Path) -> list[tuple[int, str]]:
    tree = ast.parse(path.read_text(), filename=str(path))
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found += [(node.lineno, a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            found.append((node.lineno, node.module))
    return found


def test_every_import_uses_the_neuralao_name():
    stale = [
        f"{p.relative_to(ROOT)}:{line} imports {name}"
        for p in _python_files()
        for line, name in _imports(p)
        if name.split(".")[0] in LAYERS
    ]
    assert stale == []


def test_loggers_are_named_after_their_modules():
    """A literal logger name drifts when a module moves; ``__name__`` does not (third-party loggers that a
    module quiets are named by their own packages)."""
    literal = []
    for p in _python_files():
        for node in ast.walk(ast.parse(p.read_text())):
            if (
                isinstance(node, ast.Call)
                and getattr(node.func, "attr", getattr(node.func, "id", "")) == "getLogger"
                and node.args
                and isinstance(node.args[0], ast.Constant)
                and str(node.args[0].value).split(".")[0] in {"neuralao", *LAYERS}
            ):
                literal.append(f"{p.relative_to(ROOT)}:{node.lineno}")
    assert literal == []


@pytest.mark.slow
def test_wheel_installs_one_top_level_name(tmp_path):
    """``pip install .`` puts one name in site-packages: the wheel holds ``neuralao/`` (its three layers,
    the shipped models and the viewer's files) and the dist-info, nothing else."""
    src = tmp_path / "src"  # built from a copy: setuptools writes build/ and *.egg-info beside the sources
    for layer in LAYERS:
        shutil.copytree(ROOT / layer, src / layer, ignore=shutil.ignore_patterns("__pycache__"))
    for name in ("pyproject.toml", "README.md"):
        shutil.copy2(ROOT / name, src / name)
    subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "wheel",
            "--no-deps",
            "--no-build-isolation",
            "-q",
            str(src),
            "-w",
            str(tmp_path),
        ],
        check=True,
        capture_output=True,
    )
    (wheel,) = tmp_path.glob("neuralao-*.whl")
    names = zipfile.ZipFile(wheel).namelist()
    top = {n.split("/")[0] for n in names}
    assert {t for t in top if not t.endswith(".dist-info")} == {"neuralao"}
    packages = {str(Path(n).parent).replace("/", ".") for n in names if n.endswith("/__init__.py")}
    assert packages == _package_folders()
    for shipped in (ROOT / "runtime" / "models").rglob("*"):
        if shipped.is_file():
            assert f"neuralao/{shipped.relative_to(ROOT)}" in names
    assert "neuralao/runtime/viewer/index.html" in names
    assert "neuralao/runtime/host/neuralao_host.c" in names


def test_one_import_path_per_name():
    """No module imports a name only to hand it on (a ``noqa: F401`` import), and code outside the shader
    generator takes the generator's public names from the package, never also from its submodules."""
    relayed = [
        f"{p.relative_to(ROOT)}:{n}"
        for p in _python_files()
        if p.name != "__init__.py" and p.parent.name not in ("tests", "bench")
        for n, line in enumerate(p.read_text().splitlines(), 1)
        if "noqa: F401" in line
    ]
    assert relayed == []
    glsl_api = set(ast.literal_eval(_assigned(ROOT / "export" / "glsl" / "__init__.py", "__all__")))
    deep = [
        f"{p.relative_to(ROOT)}:{node.lineno} {a.name}"
        for p in _python_files()
        if ROOT / "export" / "glsl" not in p.parents
        for node in ast.walk(ast.parse(p.read_text()))
        if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("neuralao.export.glsl.")
        for a in node.names
        if a.name in glsl_api
    ]
    assert deep == []


def _assigned(path: Path, name: str) -> str:
    for node in ast.parse(path.read_text()).body:
        if isinstance(node, ast.Assign) and any(getattr(t, "id", None) == name for t in node.targets):
            return ast.unparse(node.value)
    raise AssertionError(f"{path} assigns no {name}")
