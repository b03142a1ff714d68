#!/usr/bin/env bash
# Print the path of a working Python 3.12 interpreter, or fail with one clear line.
# ros-jazzy-rclpy ships cp312 wheels only, so no other version will do.
set -u
candidates=()
if command -v pyenv >/dev/null 2>&1; then
  root=$(pyenv root 2>/dev/null)
  for p in $(ls -d "$root"/versions/3.12.*/bin/python3.12 2>/dev/null | sort -V -r); do
    candidates+=("$p")
  done
fi
for p in /usr/bin/python3.12 /usr/local/bin/python3.12 "$(command -v python3.12 2>/dev/null)"; do
  [ -n "$p" ] && candidates+=("$p")
done
for p in "${candidates[@]}"; do
  if [ -x "$p" ] && "$p" -c 'import sys, venv; assert sys.version_info[:2] == (3, 12)' 2>/dev/null; then
    echo "$p"
    exit 0
  fi
done
echo "error: Python 3.12 not found (ros-jazzy-rclpy needs it): install it, e.g. 'pyenv install 3.12', or set PYTHON=/path/to/python3.12" >&2
exit 1
