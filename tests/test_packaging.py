"""The package as users install it: a wheel built from this tree holds every file the program reads, and the
commands run from that wheel alone, outside the source tree (no ``companion/`` beside it to fall back on).

The wheel is built offline (``pip wheel --no-deps --no-build-isolation``, setuptools and wheel from the test
extras) and unpacked into a folder; the commands run with ``python -S`` and PYTHONPATH set to that folder then
the venv's site-packages, so neither the editable install (a .pth finder) nor the working directory can supply
``companion``."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import sysconfig
import zipfile
from email.parser import Parser
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
#: files under companion/ that are not part of the program (bytecode caches)
SKIP_PARTS = {"__pycache__"}
#: a vehicle preset shipped in companion/sim/presets (package data)
PRESET = "copter"


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("wheel")
    build = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q",
                            "-w", str(out), str(ROOT)], capture_output=True, text=True, timeout=300)
    if build.returncode != 0 and "invalid command 'bdist_wheel'" in build.stderr + build.stdout:
        pytest.skip("the 'wheel' package is not installed (pip install -e '.[test]' brings it)")
    assert build.returncode == 0, build.stderr[-2000:]
    (whl,) = out.glob("*.whl")
    return whl


def _source_files() -> set[str]:
    pkg = ROOT / "companion"
    return {p.relative_to(ROOT).as_posix() for p in pkg.rglob("*")
            if p.is_file() and not SKIP_PARTS & set(p.parts) and p.suffix not in (".pyc", ".pyo")}


def test_the_wheel_is_named_for_pypi_and_holds_every_file_of_the_package(wheel):
    names = set(zipfile.ZipFile(wheel).namelist())
    missing = sorted(_source_files() - names)
    assert not missing, f"files of companion/ not in the wheel (add them to package-data): {missing}"
    meta_name = next(n for n in names if n.endswith(".dist-info/METADATA"))
    meta = Parser().parsestr(zipfile.ZipFile(wheel).read(meta_name).decode())
    # "companion" on the package index is an unrelated project: pip install companion must not be our name
    assert meta["Name"] == "companion-gyro"
    entry = zipfile.ZipFile(wheel).read(meta_name.replace("METADATA", "entry_points.txt")).decode()
    assert "companion = companion.cli.main:main" in entry


def _runner(wheel: Path, tmp: Path):
    site = tmp / "site"
    zipfile.ZipFile(wheel).extractall(site)
    work = tmp / "work"
    work.mkdir()
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(site), sysconfig.get_paths()["purelib"],
                                                       sysconfig.get_paths()["platlib"]]))

    def run(*args, ok=(0,)):
        r = subprocess.run([sys.executable, "-S", "-m", "companion", *args], cwd=work, env=env,
                           capture_output=True, text=True, timeout=240)
        assert r.returncode in ok, f"{args}: rc {r.returncode}\n{r.stdout[-1500:]}\n{r.stderr[-1500:]}"
        assert "Traceback" not in r.stderr, r.stderr
        return r

    return site, work, run


def test_every_command_runs_from_the_wheel_outside_the_source_tree(wheel, tmp_path):
    site, work, run = _runner(wheel, tmp_path)
    where = subprocess.run([sys.executable, "-S", "-c", "import companion; print(companion.__file__)"], cwd=work,
                           env={**os.environ, "PYTHONPATH": str(site)}, capture_output=True, text=True)
    assert where.stdout.strip().startswith(str(site)), where.stdout + where.stderr

    run("example", "config", "--out", "config.yaml")
    run("example", "model", "--out", "model.yaml")
    # short records: what is checked is that each command finds what it reads in the wheel, not its figures
    run("simulate", "model.yaml", "--duration", "40", "--out", "sim.tlog", "--seed", "3")
    run("simulate", "--vehicle", "--preset", PRESET, "--imus", "2", "--duration", "30", "--out", "vehicle.tlog", "--seed", "3")
    assert "RAW_IMU" in run("inspect", "sim.tlog").stdout
    run("analyze", "sim.tlog", "--json", "a.json", "--config", "config.yaml")
    streams = json.loads((work / "a.json").read_text())
    assert streams, "analyze wrote no result"
    gap = run("gap", "sim.tlog", "--model", "model.yaml", "--axis", "gx").stdout
    assert "gx" in gap
    run("gap", "sim.tlog", "--datasheet", "MPU-6000", "--axis", "gx")  # the datasheets file inside the wheel
    run("compensate", "sim.tlog", "--axis", "gx", "--duration", "20", ok=(0, 1))
    run("run", "--source", "vehicle.tlog", "--no-state", "--report", "alarms.html")
    assert "var CPlot" in (work / "alarms.html").read_text()  # the plotting module inlined from the wheel's data
    run("fleet", "simulate", "fleet", "--vehicles", "1", "--flights", "1", "--duration", "30")
    for command in ("sim-autopilot", "fleet analyze", "fleet report"):
        run(*command.split(), "--help")
