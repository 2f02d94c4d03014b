"""The wheel built from this tree installs (not editable) into a fresh venv outside the repo and runs
there: `hcgym data build` reads its inputs from the installed package and the pinned registry
packages, a gold episode scores from that build, and `hcgym view` serves the viewer's page and
assets out of site-packages.

Installing every dependency from the registry into the fresh venv takes minutes (torch, ray,
deepspeed ...), so the wheel goes in with `--no-deps` and a .pth file then puts this checkout's .venv
site-packages behind the venv's own (docs/integrations.md, "Installing the wheel"). That directory
holds the checkout's editable-install hook, but a path named in a .pth file is not a site directory:
its .pth files (the hook) are never run, so the repo itself stays off sys.path, which
`test_the_venv_imports_the_installed_packages_not_the_repo` checks."""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
import sysconfig
import time
import urllib.request
import venv
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SHIPPED = ("envs", "actors", "learner", "kb_service", "evals", "viewer", "modeling")
# A domain whose build and episodes need no other domain's build: one registry package (drugdose).
DOMAIN = "obstetrics"
TIMINGS: dict[str, float] = {}


def _source_files() -> list[str]:
    """What the build reads from a clone of this tree: pyproject.toml, the readme it names, and the
    shipped packages' files (tracked, plus new ones git does not ignore)."""
    out = subprocess.run(["git", "ls-files", "-co", "--exclude-standard", "-z", "--", *SHIPPED], cwd=ROOT,
                         capture_output=True, check=True).stdout.decode()
    return ["README.md", "pyproject.toml"] + sorted(p for p in out.split("\0") if p and (ROOT / p).is_file())


def _run(cmd: list[str], *, env: dict[str, str], cwd: Path, timeout: float = 120) -> subprocess.CompletedProcess:
    proc = subprocess.run(cmd, env=env, cwd=cwd, capture_output=True, text=True, timeout=timeout, check=False)
    assert proc.returncode == 0, f"{' '.join(map(str, cmd))} exited {proc.returncode}:\n{proc.stdout}\n{proc.stderr}"
    return proc


@pytest.fixture(scope="module")
def installed(tmp_path_factory):
    """(wheel, venv dir, its site-packages, environment for its commands, a work dir outside the repo,
    the source files the wheel was built from)."""
    tmp = tmp_path_factory.mktemp("wheel")
    assert ROOT not in tmp.parents, f"{tmp} is inside the repo"

    # Built from a copy of the tree: building in the checkout writes build/lib, whose leftovers from
    # an earlier build (a deleted module) setuptools would put into the wheel.
    start = time.perf_counter()
    src = tmp / "src"
    files = _source_files()
    for rel in files:
        (src / rel).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(ROOT / rel, src / rel)
    dist = tmp / "dist"
    _run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "--no-cache-dir", "-q",
          "-w", str(dist), str(src)], env=dict(os.environ), cwd=tmp)
    wheels = list(dist.glob("healthcare_ai_gym-*.whl"))
    assert len(wheels) == 1, wheels
    TIMINGS["build wheel"] = time.perf_counter() - start

    start = time.perf_counter()
    env_dir = tmp / "venv"
    venv.EnvBuilder(with_pip=False).create(env_dir)
    python = env_dir / "bin" / "python"
    _run([sys.executable, "-m", "pip", "--python", str(python), "install", "--no-deps", "--no-index",
          "--no-cache-dir", "-q", str(wheels[0])], env=dict(os.environ), cwd=tmp)
    purelib = subprocess.run([python, "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                             capture_output=True, text=True, check=True).stdout.strip()
    (Path(purelib) / "hcgym_test_dependencies.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    TIMINGS["venv + install"] = time.perf_counter() - start

    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV", "PYTHONHOME")}
    env.update(PATH=f"{env_dir / 'bin'}{os.pathsep}{env.get('PATH', '')}", VIRTUAL_ENV=str(env_dir),
               HCGYM_DATA_DIR=str(tmp / "data"))
    work = tmp / "work"
    work.mkdir()
    yield wheels[0], env_dir, Path(purelib), env, work, files
    print("\nwheel test timings: " + ", ".join(f"{k} {v:.1f}s" for k, v in TIMINGS.items()))


def test_the_wheel_holds_the_shipped_files_and_nothing_else(installed):
    wheel, files = installed[0], installed[-1]
    with zipfile.ZipFile(wheel) as zf:
        names = zf.namelist()
    payload = {n for n in names if ".dist-info/" not in n}
    expected = {p for p in files if p.split("/", 1)[0] in SHIPPED}
    assert payload - expected == set(), f"in the wheel but not in the tree: {sorted(payload - expected)}"
    assert expected - payload == set(), (f"in a shipped package but left out of the wheel: {sorted(expected - payload)}; "
                                         "add their pattern to [tool.setuptools.package-data] in pyproject.toml")
    assert not [n for n in names if n.startswith(("tests/", "build/", "configs/", "bench/")) or "__pycache__" in n]
    entry_points = next(n for n in names if n.endswith(".dist-info/entry_points.txt"))
    with zipfile.ZipFile(wheel) as zf:
        assert "hcgym = envs.cli:main" in zf.read(entry_points).decode()


def test_the_venv_imports_the_installed_packages_not_the_repo(installed):
    _, env_dir, purelib, env, work, _ = installed
    probe = ("import importlib.metadata as md, importlib.util, json, sys\n"
             f"pkgs = {SHIPPED!r}\n"
             "dist = md.distribution('healthcare-ai-gym')\n"
             "print(json.dumps({'path': sys.path, 'prefix': sys.prefix,\n"
             "  'origins': {p: importlib.util.find_spec(p).origin for p in pkgs},\n"
             "  'dist': str(dist.locate_file('')), 'direct_url': json.loads(dist.read_text('direct_url.json'))}))")
    got = json.loads(_run([env_dir / "bin" / "python", "-c", probe], env=env, cwd=work).stdout)
    assert Path(got["prefix"]) == env_dir
    assert (env_dir / "bin" / "hcgym").read_text().splitlines()[0] == f"#!{env_dir / 'bin' / 'python'}"
    for pkg, origin in got["origins"].items():
        assert Path(origin) == purelib / pkg / "__init__.py", f"{pkg} imported from {origin}"
    assert Path(got["dist"]) == purelib
    assert "editable" not in json.dumps(got["direct_url"]), got["direct_url"]
    deps = sysconfig.get_paths()["purelib"]
    inside = [p for p in got["path"] if p and (Path(p).resolve() == ROOT or ROOT in Path(p).resolve().parents)
              and Path(p).resolve() != Path(deps).resolve()]
    assert not inside, f"the repo is on the fresh venv's sys.path: {inside}"


def test_data_build_episode_and_viewer_run_from_the_installed_package(installed):
    _, env_dir, purelib, env, work, _ = installed
    hcgym = str(env_dir / "bin" / "hcgym")
    from envs.core.paths import domain_build_dir, package_cache_dir

    # Offline from the pinned wheels this checkout already fetched (`make data`): no network in tests.
    cache = package_cache_dir()
    assert cache.is_dir(), f"{cache}: no registry package cache; run `make data` first"
    data = Path(env["HCGYM_DATA_DIR"])
    data.mkdir()
    (data / "packages").symlink_to(cache, target_is_directory=True)

    start = time.perf_counter()
    out = _run([hcgym, "data", "build", "--only", DOMAIN, "--offline"], env=env, cwd=work).stdout
    TIMINGS[f"data build {DOMAIN}"] = time.perf_counter() - start
    built = data / "domains" / DOMAIN
    assert f"[data] {DOMAIN}:" in out and (built / "tasks.json").is_file(), out
    # Same inputs (the manifest's fingerprint), same bytes as the checkout's own build.
    reference = domain_build_dir(DOMAIN)
    fingerprint = json.loads((built / "manifest.json").read_text())["fingerprint"]
    if (reference / "manifest.json").is_file() and \
            json.loads((reference / "manifest.json").read_text())["fingerprint"] == fingerprint:
        for name in ("db.json", "tasks.json", "split_tasks.json"):
            assert (built / name).read_bytes() == (reference / name).read_bytes(), name

    # One gold episode through the public API, its score logged as a training step would be.
    run_dir = work / "run"
    episode = f"""
import json
from envs.core.paths import domain_build_dir
from envs.env import HealthcareGymEnv
from learner.metrics import MetricsSink
env = HealthcareGymEnv(domain={DOMAIN!r}, split="test", max_turns=10)
env.reset(seed=0)
task = env.task
for action in task.evaluation_criteria.actions:
    assert env.call_tool(action.name, action.arguments, message="").ok
result = env.call_tool("submit_answer", {{"answer": task.correct_answer, "reasoning": "gold"}}, message="")
assert result.done and result.end.reason == "answer", result
sink = MetricsSink({str(run_dir)!r}, tensorboard=False, ray_metrics=False)
sink.write({{"step": 1, "reward/mean": result.end.reward}})
sink.close()
print(json.dumps({{"reward": result.end.reward, "correct": result.end.is_correct, "task": task.id,
                  "data": str(domain_build_dir({DOMAIN!r}))}}))
"""
    start = time.perf_counter()
    score = json.loads(_run([env_dir / "bin" / "python", "-c", episode], env=env, cwd=work).stdout.splitlines()[-1])
    TIMINGS["gold episode"] = time.perf_counter() - start
    assert score["correct"] is True and score["reward"] > 0.5, score
    assert Path(score["data"]) == built

    start = time.perf_counter()
    viewer = subprocess.Popen([hcgym, "view", str(run_dir), "--port", "0"], env=env, cwd=work,
                              stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        lines = []
        for line in viewer.stdout:
            lines.append(line)
            if "open http://" in line:
                break
        url = re.search(r"open (http://127\.0\.0\.1:\d+)", "".join(lines))
        assert url, "".join(lines)
        base = url.group(1)

        def get(path: str) -> bytes:
            with urllib.request.urlopen(base + path, timeout=10) as response:
                assert response.status == 200, path
                return response.read()

        static = purelib / "viewer" / "static"
        assert get("/") == (static / "index.html").read_bytes() == (ROOT / "viewer/static/index.html").read_bytes()
        assert get("/static/app.js") == (ROOT / "viewer/static/app.js").read_bytes()
        assert get("/static/style.css") == (ROOT / "viewer/static/style.css").read_bytes()
        metrics = json.loads(get("/api/run/metrics?source=s0"))
        assert [row["reward/mean"] for row in metrics["train"]] == [score["reward"]], metrics
    finally:
        viewer.terminate()
        viewer.wait(timeout=10)
    TIMINGS["hcgym view"] = time.perf_counter() - start
