"""Packaging metadata: pyproject.toml, environment.yml and the console script agree."""
import re
from importlib import metadata
from pathlib import Path

import pytest

try:
    import tomllib
except ImportError:  # Python 3.10
    tomllib = pytest.importorskip("tomli")

ROOT = Path(__file__).resolve().parent.parent


def _canonical(name: str) -> str:
    return re.sub(r"[-_.]+", "-", name).lower()


def _parse_requirement(req: str) -> tuple[str, str]:
    """('name', 'sorted,specifiers') of a requirement such as 'jupyter-book>=1.0.4,<2' (no markers or extras)."""
    req = req.split(";")[0].strip()
    m = re.match(r"^([A-Za-z0-9][A-Za-z0-9._-]*)\s*(\[[^\]]*\])?\s*(.*)$", req)
    assert m, f"cannot parse requirement {req!r}"
    specs = ",".join(sorted(s.replace(" ", "") for s in m.group(3).split(",") if s.strip()))
    return _canonical(m.group(1)), specs


def _pyproject() -> dict:
    with open(ROOT / "pyproject.toml", "rb") as fh:
        return tomllib.load(fh)


def _pyproject_requirements() -> dict[str, str]:
    project = _pyproject()["project"]
    reqs = list(project.get("dependencies", []))
    for extra in project.get("optional-dependencies", {}).values():
        reqs += extra
    out: dict[str, str] = {}
    for r in reqs:
        name, spec = _parse_requirement(r)
        assert out.get(name, spec) == spec, f"{name} has different version ranges in pyproject.toml"
        out[name] = spec
    return out


def _environment_yml() -> tuple[dict, list[str]]:
    """A tiny reader for the subset of YAML that environment.yml uses: top-level keys, lists, one nested pip list."""
    top: dict[str, object] = {}
    pip: list[str] = []
    key = None
    in_pip = False
    for raw in (ROOT / "environment.yml").read_text(encoding="utf-8").splitlines():
        line = raw.split(" #")[0].rstrip() if not raw.lstrip().startswith("#") else ""
        if not line.strip():
            continue
        indent = len(line) - len(line.lstrip())
        text = line.strip()
        if indent == 0:
            in_pip = False
            key, _, value = text.partition(":")
            top[key] = value.strip() or []
        elif text.startswith("- "):
            item = text[2:].strip()
            if item == "pip:":
                in_pip, pip_indent = True, indent
                continue
            if in_pip and indent > pip_indent:
                pip.append(item)
            else:
                in_pip = False
                top[key].append(item)  # type: ignore[union-attr]
    return top, pip


def test_environment_yml_lists_the_pyproject_packages():
    top, pip = _environment_yml()
    env = {}
    for r in pip:
        assert r != "-e .", "the package itself is installed separately"
        name, spec = _parse_requirement(r)
        assert name not in env, f"{name} listed twice in environment.yml"
        env[name] = spec
    assert env == _pyproject_requirements()


def test_environment_yml_header():
    top, _ = _environment_yml()
    assert top["name"] == "rfmap"
    assert top["channels"] == ["conda-forge"]
    assert "python=3.11" in top["dependencies"] and "pip" in top["dependencies"]


def test_requirement_parser():
    assert _parse_requirement("jupyter-book>=1.0.4,<2") == ("jupyter-book", "<2,>=1.0.4")
    assert _parse_requirement("Jupyter_Book >= 1.0.4, <2") == ("jupyter-book", "<2,>=1.0.4")
    assert _parse_requirement("numpy") == ("numpy", "")


def test_console_script_is_declared():
    scripts = _pyproject()["project"]["scripts"]
    assert scripts["rfmap"] == "rfmap.cli:entry"
    try:
        dist = metadata.distribution("rfmap")
    except metadata.PackageNotFoundError:
        pytest.skip("rfmap is not installed")
    eps = {ep.name: ep.value for ep in dist.entry_points if ep.group == "console_scripts"}
    assert eps.get("rfmap") == "rfmap.cli:entry"


def test_package_data_declared():
    data = _pyproject()["tool"]["setuptools"]["package-data"]["rfmap"]
    assert "data/*.json" in data
    assert (ROOT / "src" / "rfmap" / "data" / "figures.json").exists()


def test_makefile_pins_torch_before_the_package():
    text = (ROOT / "Makefile").read_text(encoding="utf-8")
    assert "torch==2.13.0" in text
    assert text.index("$(TORCH)\n") < text.index('-e ".[dev,lab,geo]"')
