"""Start-up: `kincal --help`, `import kincal` and usage errors do not load the heavy
libraries (Pinocchio, scipy, matplotlib); the public API still resolves lazily."""

import subprocess
import sys

HEAVY = ("pinocchio", "scipy", "matplotlib", "yourdfpy", "threadpoolctl", "xacro")

PROBE = """
import sys
from kincal.cli import main
try:
    main({argv!r})
except SystemExit:
    pass
print("LOADED:" + ",".join(m for m in {heavy!r} if m in sys.modules))
"""


def _loaded(argv) -> list[str]:
    out = subprocess.run([sys.executable, "-c", PROBE.format(argv=argv, heavy=HEAVY)],
                         capture_output=True, text=True, timeout=60, check=True).stdout
    last = out.strip().splitlines()[-1]
    assert last.startswith("LOADED:"), out
    return [m for m in last[len("LOADED:"):].split(",") if m]


def test_help_and_usage_errors_load_nothing_heavy():
    assert _loaded(["--help"]) == []
    assert _loaded(["calibrate", "--help"]) == []
    assert _loaded(["calibrate"]) == []  # a usage error: exit 2 before any work


def test_import_kincal_is_light_and_the_api_resolves():
    code = ("import sys, kincal; light = [m for m in %r if m in sys.modules]; "
            "from kincal import Robot, calibrate, Measurements, select_poses; "
            "import kincal as k; assert k.Robot is Robot and 'Robot' in dir(k); "
            "print(light, 'pinocchio' in sys.modules)") % (HEAVY,)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=60, check=True).stdout.strip()
    assert out == "[] True"


def test_unknown_attribute_is_an_attribute_error():
    import kincal

    try:
        kincal.NoSuchThing  # noqa: B018
    except AttributeError as exc:
        assert "NoSuchThing" in str(exc)
    else:
        raise AssertionError("kincal.NoSuchThing resolved")


def test_help_of_every_command_loads_no_numpy():
    code = ("import sys\nfrom kincal.cli import main\n"
            "for c in ('calibrate', 'evaluate', 'analyze', 'simulate', 'plan', 'compensate', "
            "'demo'):\n    try:\n        main([c, '--help'])\n    except SystemExit:\n        pass\n"
            "print('NUMPY:', 'numpy' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=60, check=True).stdout
    assert out.strip().splitlines()[-1] == "NUMPY: False"


BLAS_PROBE = """
import os
import kincal.cli  # the command line's entry, before anything loads numpy
import numpy
import threadpoolctl

threads = [i["num_threads"] for i in threadpoolctl.threadpool_info()
           if i["internal_api"] == "openblas"]
print("BLAS:", os.environ["OPENBLAS_NUM_THREADS"], max(threads) if threads else "none")
"""


def _blas(env_value=None):
    import os

    env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_NUM_THREADS"}
    if env_value is not None:
        env["OPENBLAS_NUM_THREADS"] = env_value
    out = subprocess.run([sys.executable, "-c", BLAS_PROBE], capture_output=True, text=True,
                         timeout=60, check=True, env=env).stdout.split()
    return out[1], out[2]


def test_the_command_line_runs_blas_with_one_thread_unless_told():
    """The command line sets OPENBLAS_NUM_THREADS=1 before numpy loads (no spinning worker
    pools: docs/results.md "Speed"); a value the user set is kept."""
    value, threads = _blas()
    assert value == "1" and threads in ("1", "none")
    assert _blas("2")[0] == "2"
