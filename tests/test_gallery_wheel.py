"""The repository holds what `pamjax reproduce` needs (issue 31): the wheel, installed in a fresh virtual environment
outside the checkout, runs the whole quick gallery from its own files (scripts, procedures, bench recordings). The
environment reuses this interpreter's installed dependencies (a `.pth` line to its site-packages: no download of JAX)
and installs the wheel with `--no-deps`; building the wheel fetches hatchling (network). What is checked: the
wheel's contents (`pyproject.toml`'s build targets) and `pamjax.gallery` with `pamjax/data` run from them."""

import os
import pathlib
import subprocess
import sys
import sysconfig
import venv
import zipfile

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]


def _clean_env(home):
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME", "VIRTUAL_ENV")}
    env.update(HOME=str(home), MPLBACKEND="Agg")
    return env


@pytest.mark.slow
def test_reproduce_runs_from_an_installed_wheel(tmp_path):
    wheels = tmp_path / "wheels"
    build = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--quiet", "-w", str(wheels), str(ROOT)],
                           capture_output=True, text=True, timeout=600)
    assert build.returncode == 0, build.stdout + build.stderr
    [wheel] = wheels.glob("pamjax-*.whl")
    names = zipfile.ZipFile(wheel).namelist()
    for needed in ("pamjax/gallery/scripts/p000_01_force_laws.py", "pamjax/gallery/procedures/regulator.py",
                   "pamjax/data/hybrid-reference-bench/E4.npz", "pamjax/data/hybrid-reference-bench/README.md",
                   "pamjax/data/DMSP-20-300_force_map_long.csv"):
        assert needed in names, needed

    env_dir = tmp_path / "env"
    venv.EnvBuilder(with_pip=True).create(env_dir)
    python = env_dir / "bin" / "python"
    site = subprocess.run([str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                          capture_output=True, text=True, check=True).stdout.strip()
    host = {sysconfig.get_paths()["purelib"], sysconfig.get_paths()["platlib"]}
    (pathlib.Path(site) / "_host_packages.pth").write_text("\n".join(sorted(host)) + "\n")
    work = tmp_path / "work"  # outside the checkout: nothing of it on the path
    work.mkdir()
    env = _clean_env(tmp_path)
    install = subprocess.run([str(python), "-m", "pip", "install", "--no-deps", "--no-index", "--quiet", str(wheel)],
                             capture_output=True, text=True, cwd=work, env=env, timeout=300)
    assert install.returncode == 0, install.stdout + install.stderr
    where = subprocess.run([str(python), "-c", "import pamjax, pamjax.gallery.toolkit as t; "
                            "print(pamjax.__file__); print(t.bench_folder())"],
                           capture_output=True, text=True, cwd=work, env=env, check=True).stdout.split()
    assert all(w.startswith(str(env_dir)) for w in where), where  # the wheel's files, not the checkout's

    run = subprocess.run([str(env_dir / "bin" / "pamjax"), "reproduce", "--quick", "--out", "papers"],
                         capture_output=True, text=True, cwd=work, env=env, timeout=900)
    assert run.returncode == 0, run.stdout[-3000:] + run.stderr[-3000:]
    index = (work / "papers" / "index.md").read_text()
    assert "**number missing**" not in index and "**not run**" not in index
    assert len(list((work / "papers").glob("p0*/*.png"))) >= 15
