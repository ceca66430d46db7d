# Sourced by scripts/test and scripts/demo: sets PY to a Python that pip may install this package into.
# That is python3 itself where pip works there; where the system owns it (PEP 668's EXTERNALLY-MANAGED, as on
# Debian 12 and Ubuntu 23.04 on) or it has no pip, a virtual environment of the checkout's own, .venv, made once
# (as root with apt-get, python3-venv installed first where it is missing), whose bin/ goes first on PATH so that
# the console scripts (fitgen, tactile-host, tactile-hil) are found.

PY=python3
if ! command -v python3 >/dev/null 2>&1; then
    echo "error: no python3 on PATH; install Python 3.10 or later (Debian: apt-get install python3 python3-venv)" >&2
    exit 1
fi
# 0: pip may install into python3; 1: it may not (the system's, or no pip); 3: too old
takes_pip=0
python3 - <<'PYEOF' || takes_pip=$?
import os, sys, sysconfig
if sys.version_info < (3, 10):
    sys.exit(3)
managed = sys.prefix == sys.base_prefix and os.path.exists(os.path.join(sysconfig.get_path("stdlib"), "EXTERNALLY-MANAGED"))
try:
    import pip  # noqa: F401
except ImportError:
    sys.exit(1)
sys.exit(1 if managed else 0)
PYEOF
if [ "$takes_pip" = 3 ]; then
    echo "error: $(python3 --version 2>&1) is too old: this package needs Python 3.10 or later" >&2
    exit 1
fi
if [ "$takes_pip" != 0 ]; then
    # made anew (--clear) where a run was stopped half-way or python3 was upgraded under it: no pip to run there
    if ! .venv/bin/python -c 'import pip' >/dev/null 2>&1; then
        echo "python3 is the system's (or has no pip): making a virtual environment in .venv" >&2
        if ! python3 -m venv --clear .venv >/dev/null 2>&1; then
            rm -rf .venv
            if command -v apt-get >/dev/null 2>&1 && [ "$(id -u)" = 0 ]; then
                apt-get update -qq
                DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends python3-venv >/dev/null
            fi
            if ! python3 -m venv --clear .venv; then
                rm -rf .venv
                echo "error: python3 cannot make a virtual environment; install python3-venv (sudo apt-get install python3-venv)" >&2
                exit 1
            fi
        fi
    fi
    PY="$PWD/.venv/bin/python"
    export PATH="$PWD/.venv/bin:$PATH"
    export VIRTUAL_ENV="$PWD/.venv"
fi
