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
