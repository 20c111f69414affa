# Sourced by tools/test.sh and .ci/run: creates the virtual environment .venv (once), installs the test
# peers of requirements-test.txt into it, and puts it first on PATH, so that every `python3` the tests
# start is the environment's. SOFTCONTACT_PYTHON picks the interpreter that creates it (python3).
#
# A stock Debian 12 or Ubuntu 24.04 may lack the venv module (package python3-venv): as root the script
# installs it with apt-get; otherwise it stops and prints the command to run.
venv=.venv
base_python=${SOFTCONTACT_PYTHON:-python3}
if [ ! -x "$venv/bin/python3" ] || ! "$venv/bin/python3" -c 'import sys' 2>/dev/null; then
  rm -rf "$venv"
  if ! "$base_python" -m venv "$venv" 2>/dev/null; then
    rm -rf "$venv"
    if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
      echo "python-env: the venv module is missing; installing python3-venv with apt-get"
      apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq python3-venv >/dev/null
      "$base_python" -m venv "$venv"
    else
      echo "python-env: $base_python cannot create a virtual environment; run: sudo apt-get install python3-venv" >&2
      exit 1
    fi
  fi
fi
"$venv/bin/python3" -m pip install --quiet --disable-pip-version-check -r requirements-test.txt
export PATH="$PWD/$venv/bin:$PATH"
export SOFTCONTACT_PYTHON="$PWD/$venv/bin/python3"
