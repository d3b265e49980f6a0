#!/usr/bin/env bash
# Install the benchmark peers, FIGAROH and pybotics, each into its own virtual
# environment under .peers/ (git-ignored), from PyPI, at pinned versions.
#
#   bash scripts/peers/setup_peers.sh            # create / update, print versions
#   PYTHON=python3.12 bash scripts/peers/setup_peers.sh
#   FORCE=1 bash scripts/peers/setup_peers.sh    # rebuild both venvs from scratch
#
# Idempotent: a venv whose stamp matches the pinned set (and whose peer imports) is
# left alone. Nothing is vendored: pip resolves every package from the index.
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
PEERS="$ROOT/.peers"
PYTHON="${PYTHON:-python3}"
mkdir -p "$PEERS"

"$PYTHON" - <<'EOF' || { echo "setup_peers: need Python >= 3.10 (set PYTHON=...)" >&2; exit 1; }
import sys
sys.exit(0 if sys.version_info >= (3, 10) else 1)
EOF

# ---- pinned sets (pip freeze of a working install, 2 cores / Linux x86_64, CPython 3.11)
# FIGAROH 1.0.2 needs pin>=3.7,<5 with a matching ndcurves; it runs with numpy 2.
FIGAROH_PINS="
figaroh==1.0.2
pin==4.1.0
libpinocchio==4.1.0
eigenpy==3.13.0
coal==3.0.3
libcoal==3.0.3
ndcurves==2.3.0
libndcurves==2.3.0
cmeel==0.62.0
cmeel-assimp==6.0.5
cmeel-boost==1.90.0
cmeel-console-bridge==1.0.2.3
cmeel-octomap==1.10.0
cmeel-qhull==8.0.2.1
cmeel-tinyxml2==11.0.0
cmeel-urdfdom==6.0.0
cmeel-zlib==1.3.2
numpy==2.4.6
scipy==1.17.1
pandas==3.1.1
PyYAML==6.0.3
matplotlib==3.11.2
meshcat==0.3.2
numdifftools==0.11.2
PICOS==2.6.2
cvxopt==1.3.3
rospkg==1.6.3
catkin-pkg==1.1.1
"
# pybotics 3.1.2 (last release, 2023) declares numpy<2 and scipy<2.
PYBOTICS_PINS="
pybotics==3.1.2
numpy==1.26.4
scipy==1.17.1
attrs==26.1.0
"

install_peer() {  # name, pins, import check
  local name="$1" pins="$2" check="$3"
  local venv="$PEERS/$name-venv" cons="$PEERS/$name.constraints.txt"
  local stamp="$venv/.kincal-peer-stamp"
  printf '%s\n' $pins > "$cons"
  local want
  want="$(cat "$cons" | sha256sum | cut -d' ' -f1) $("$PYTHON" -c 'import sys; print("%d.%d" % sys.version_info[:2])')"
  if [[ "${FORCE:-0}" == 1 ]]; then rm -rf "$venv"; fi
  if [[ -f "$stamp" && "$(cat "$stamp")" == "$want" ]] && "$venv/bin/python" -W ignore -c "$check" 2>/dev/null; then
    echo "[$name] up to date: $venv"
    return
  fi
  [[ -x "$venv/bin/python" ]] || "$PYTHON" -m venv "$venv"
  echo "[$name] installing into $venv"
  # the peer's top-level requirement plus every pin as a constraint
  "$venv/bin/python" -m pip install --quiet --disable-pip-version-check \
      -c "$cons" "$(head -n1 "$cons")"
  "$venv/bin/python" -W ignore -c "$check"
  echo "$want" > "$stamp"
}

install_peer figaroh "$FIGAROH_PINS" \
  "import figaroh.calibration, pinocchio, numpy, scipy"
install_peer pybotics "$PYBOTICS_PINS" \
  "import pybotics.optimization, numpy, scipy"

echo "--- peer versions"
"$PEERS/figaroh-venv/bin/python" - <<'EOF'
import sys
from importlib.metadata import version
import pinocchio
print("figaroh-venv  python %s  figaroh %s  pin %s  numpy %s  scipy %s" % (
    sys.version.split()[0], version("figaroh"), pinocchio.__version__,
    version("numpy"), version("scipy")))
EOF
"$PEERS/pybotics-venv/bin/python" - <<'EOF'
import sys
from importlib.metadata import version
print("pybotics-venv python %s  pybotics %s  numpy %s  scipy %s" % (
    sys.version.split()[0], version("pybotics"), version("numpy"), version("scipy")))
EOF
