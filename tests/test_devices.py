"""Where work runs (pamjax/_core/devices.py): single trajectories on the CPU, batched sweeps on an accelerator when
there is one, `--device` / `device=` to choose. No GPU here: the choices are checked against fake device lists and
a JAX whose backends have not started (its configuration calls recorded), and the command line in this process."""

import os
import re
import subprocess
import sys
from dataclasses import dataclass

import jax
import pytest

import pamjax._core.devices as devices
from pamjax import PamjaxInputError
from pamjax._cli.main import main


@dataclass(frozen=True)
class Fake:
    platform: str
    id: int


CPU0, CPU1, GPU0, GPU1, TPU0 = Fake("cpu", 0), Fake("cpu", 1), Fake("gpu", 0), Fake("gpu", 1), Fake("tpu", 0)


def test_single_trajectories_go_to_the_cpu_and_sweeps_to_the_accelerator():
    available = [CPU0, CPU1, GPU0, GPU1]
    single = devices.select_devices("single", available=available)
    assert single.devices == (CPU0,) and single.reason == devices.SINGLE_REASON
    batched = devices.select_devices("batched", available=available)
    assert batched.devices == (GPU0, GPU1) and batched.reason == devices.BATCHED_REASON
    assert devices.select_devices("batched", available=[TPU0, CPU0]).devices == (TPU0,)
    # CUDA and ROCm devices are GPUs
    assert devices.select_devices("batched", available=[CPU0, Fake("cuda", 0)]).platform == "cuda"
    assert devices.select_devices("single", device="gpu", available=[CPU0, Fake("rocm", 3)]).devices == (
        Fake("rocm", 3),)


def test_without_an_accelerator_a_sweep_uses_every_cpu_device():
    choice = devices.select_devices("batched", available=[CPU0, CPU1])
    assert choice.devices == (CPU0, CPU1) and "no accelerator" in choice.reason
    assert devices.select_devices("single", available=[CPU0, CPU1]).devices == (CPU0,)
    assert devices.select_devices("single", available=[GPU0]).devices == (GPU0,)  # a process without a CPU device


def test_the_device_asked_for_wins_and_is_said():
    available = [CPU0, CPU1, GPU0, GPU1]
    assert devices.select_devices("batched", "cpu", available).devices == (CPU0, CPU1)
    choice = devices.select_devices("single", "GPU", available)
    assert choice.devices == (GPU0,) and choice.statement() == "running on 1 gpu device (--device gpu)"
    assert devices.select_devices("batched", "gpu", available).statement() == "running on 2 gpu devices " \
                                                                                 "(--device gpu)"


@pytest.mark.parametrize("work, device, match", [
    ("single", "tpu", r"device='tpu': JAX finds no TPU here \(available: cpu, gpu\)"),
    ("single", "metal", r"device must be one of \('auto', 'cpu', 'gpu', 'tpu'\), got 'metal'"),
    ("lanes", "auto", r"work must be one of \('single', 'batched'\), got 'lanes'"),
])
def test_an_unknown_or_absent_device_is_an_input_error_naming_it(work, device, match):
    with pytest.raises(PamjaxInputError, match=match):
        devices.select_devices(work, device, [CPU0, GPU0])


def test_the_command_sets_its_platforms_before_jax_starts(monkeypatch):
    # A fresh process's view: backends not started; what the command line sets is recorded, nothing starts.
    updates, before = [], jax.config.jax_platforms  # "cpu" where a command ran in this process before (main(argv))
    monkeypatch.setattr("pamjax._core.private.jax_backends_initialized", lambda: False)
    monkeypatch.setattr(jax.config, "update", lambda name, value: updates.append((name, value)))

    _, line = devices.for_command("single", "auto", environ={})
    assert updates == [("jax_platforms", "cpu")] and line.startswith("running on the CPU (single-trajectory work")
    updates.clear()
    _, line = devices.for_command("batched", "auto", environ={})
    assert updates == [] and "GPU/TPU if JAX finds one, else every CPU core" in line  # JAX's default platforms
    _, line = devices.for_command("batched", "cpu", environ={})
    assert updates == [("jax_platforms", "cpu")] and line == "running on the CPU (--device cpu)"
    updates.clear()
    _, line = devices.for_command("single", "auto", environ={"JAX_PLATFORMS": "cuda"})  # the user's setting wins
    assert updates == [] and "JAX_PLATFORMS=cuda" in line

    def no_gpu(platform=None):
        raise RuntimeError("Unknown backend: 'gpu' requested, but no platforms that are instances of gpu are present")

    monkeypatch.setattr(jax, "devices", no_gpu)
    with pytest.raises(PamjaxInputError, match=r"--device gpu: JAX cannot start a GPU here \(Unknown backend"):
        devices.for_command("single", "gpu", environ={})
    assert updates[-2:] == [("jax_platforms", ""), ("jax_platforms", before)]  # and put back


def test_a_fresh_command_process_runs_single_trajectories_on_the_cpu_platform_only():
    # The real thing in a new process: for_command before any JAX computation leaves JAX with the CPU platform.
    code = ("import jax; import pamjax._core.devices as d; ctx, line = d.for_command('single', environ={}); "
            "print(jax.config.jax_platforms, [x.platform for x in jax.devices()]); print(line)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.splitlines()[0] == "cpu ['cpu']"


def test_the_command_line_says_where_it_runs_and_refuses_an_absent_device(tmp_path, capsys):
    jax.devices()  # JAX running, as in a program that calls main(argv): the choice among its devices
    config = tmp_path / "bad.toml"
    config.write_text("[model]\npreset = \"no-such-preset\"\n")
    assert main(["simulate", str(config), "--out", str(tmp_path / "out")]) == 2  # a config error, after the line
    out, err = capsys.readouterr()
    assert re.search(r"^pamjax simulate: running on 1 cpu device \(single-trajectory work", out, re.M), out
    for argv in (["simulate", str(config), "--device", "tpu"], ["--device", "tpu", "simulate", str(config)]):
        assert main([*argv, "--out", str(tmp_path / "out")]) == 2  # given before the command too (was: ignored)
        out, err = capsys.readouterr()
        assert "pamjax simulate: error: device='tpu': JAX finds no TPU here (available: cpu)" in err, (argv, err)


def test_a_jax_platforms_that_cannot_start_is_an_input_error_naming_it(monkeypatch):
    # JAX_PLATFORMS=tpu without a TPU: `pamjax simulate` reported an internal error at the first computation
    # ("RuntimeError: Unable to initialize backend 'tpu' ... please report it", status 1). Now tried first and named
    # with the platforms there are (JAX then asked for every platform, and put back).
    updates = []
    monkeypatch.setattr("pamjax._core.private.jax_backends_initialized", lambda: False)
    monkeypatch.setattr(jax.config, "update", lambda name, value: updates.append((name, value)))

    def no_tpu(platform=None):
        if platform == "cpu":
            return [CPU0]
        raise RuntimeError("Unable to initialize backend 'tpu': INTERNAL: Failed to open libtpu.so")

    monkeypatch.setattr(jax, "devices", no_tpu)
    before = jax.config.jax_platforms
    with pytest.raises(PamjaxInputError, match=r"JAX_PLATFORMS=tpu \(set in the environment\): JAX cannot start "
                                               r"it here \(Unable to initialize backend 'tpu': .*\); available: cpu\."
                                               r" Unset JAX_PLATFORMS or set it to one of those, or choose with "
                                               r"--device"):
        devices.for_command("single", "auto", environ={"JAX_PLATFORMS": "tpu"})
    assert updates == [("jax_platforms", ""), ("jax_platforms", before)]
    updates.clear()
    # not tried: a CPU-only list (it starts; a sweep still splits the CPU after this), a multi-process run's
    _, line = devices.for_command("batched", "auto", environ={"JAX_PLATFORMS": "cpu"})
    assert updates == [] and "JAX_PLATFORMS=cpu" in line
    _, line = devices.for_command("batched", "auto", environ={"JAX_PLATFORMS": "tpu"}, check=False)
    assert updates == [] and "JAX_PLATFORMS=tpu" in line


def test_the_command_refuses_an_absent_jax_platforms_with_status_2(tmp_path):
    try:
        jax.devices("tpu")
        pytest.skip("this machine has a TPU")
    except RuntimeError:
        pass
    env = dict(os.environ, JAX_PLATFORMS="tpu")
    proc = subprocess.run([sys.executable, "-m", "pamjax", "simulate", str(tmp_path / "never-read.toml"), "--out",
                           str(tmp_path / "out")], env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 2, proc.stderr
    assert re.search(r"^pamjax simulate: error: JAX_PLATFORMS=tpu \(set in the environment\): JAX cannot start it "
                     r"here .*; available: cpu", proc.stderr, re.M), proc.stderr
    assert "please report it" not in proc.stderr and not (tmp_path / "out").exists()


def test_a_platform_jax_fails_to_start_with_a_bare_assertion_is_named_as_the_others(monkeypatch):
    # JAX_PLATFORMS=cuda without CUDA: JAX's `backends()` fails `assert _default_backend is not None`, which reached
    # the user as "AssertionError: ... please report it" (status 1) where rocm or a typo gave the named input error
    monkeypatch.setattr("pamjax._core.private.jax_backends_initialized", lambda: False)
    monkeypatch.setattr(jax.config, "update", lambda name, value: None)

    def no_cuda(platform=None):
        if platform == "cpu":
            return [CPU0]
        raise AssertionError()

    monkeypatch.setattr(jax, "devices", no_cuda)
    with pytest.raises(PamjaxInputError, match=r"JAX_PLATFORMS=cuda \(set in the environment\): JAX cannot start it "
                                               r"here \(no backend of it started\); available: cpu\. Unset"):
        devices.for_command("single", "auto", environ={"JAX_PLATFORMS": "cuda"})
    with pytest.raises(PamjaxInputError, match=r"--device gpu: JAX cannot start a GPU here \(no backend of it"):
        devices.for_command("single", "gpu", environ={})


@pytest.mark.parametrize("work", ["single", "batched"])
def test_no_devices_to_choose_from_is_an_input_error(work):
    # available=[]: a bare StopIteration ("single"), or a choice without devices whose statement() raised IndexError
    with pytest.raises(PamjaxInputError, match=r"select_devices: available holds no device; pass JAX devices"):
        devices.select_devices(work, available=[])


@pytest.mark.parametrize("available, match", [
    (lambda: jax.devices("cpu")[0], r"available must be a list of JAX devices, got the one device .*: pass it in a "
                                    r"list, available=\[.*\]"),
    (CPU0, r"available must be a list of JAX devices, got the one device Fake"),
    (["cpu"], r"available holds 'cpu', not a JAX device \(a platform name: choose it with device=\.\.\., e\.g\. "
              r"device='cpu'\); pass a list of JAX devices"),
    ([CPU0, 3], r"available holds 3, not a JAX device; pass a list of JAX devices, e\.g\. jax\.devices\(\)"),
    ("cpu", r"available must be a list of JAX devices, got 'cpu'; pass"),
    (3, r"available must be a list of JAX devices, got 3; pass"),
])
def test_available_that_is_not_a_list_of_devices_is_an_input_error_naming_it(available, match):
    # one device rather than a list was a raw TypeError ("'Device' object is not iterable"), platform names an
    # AttributeError ("'str' object has no attribute 'platform'")
    available = available() if callable(available) else available  # a real device: JAX started in the test only
    with pytest.raises(PamjaxInputError, match=r"select_devices: " + match):
        devices.select_devices("single", available=available)
    assert devices.select_devices("single", available=iter([CPU0, GPU0])).devices == (CPU0,)  # any iterable serves
