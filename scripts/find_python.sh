#!/usr/bin/env bash
# Print the path of a Python >= 3.12, or explain on stderr and exit 1.
# Looks at: $SKINFIT_PYTHON, python3.13, python3.12, python3, then pyenv-managed versions.
ok() { "$1" -c 'import sys; sys.exit(0 if sys.version_info >= (3, 12) else 1)' >/dev/null 2>&1; }
for cand in "${SKINFIT_PYTHON:-}" python3.14 python3.13 python3.12 python3; do
  [ -n "$cand" ] || continue
  path=$(command -v "$cand" 2>/dev/null) || continue
  if ok "$path"; then echo "$path"; exit 0; fi
done
if command -v pyenv >/dev/null 2>&1; then
  root=$(pyenv root)
  for v in $(ls -1 "$root/versions" 2>/dev/null | sort -rV); do
    p="$root/versions/$v/bin/python"
    if [ -x "$p" ] && ok "$p"; then echo "$p"; exit 0; fi
  done
fi
echo "skinfit needs Python >= 3.12 and none was found (tried \$SKINFIT_PYTHON, python3.14/3.13/3.12, python3, pyenv versions)." >&2
echo "Install one (e.g. 'pyenv install 3.12') or set SKINFIT_PYTHON=/path/to/python3.12." >&2
exit 1
