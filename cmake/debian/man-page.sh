#!/bin/sh
# The manual page of one shipped program from its --help (help2man), gzipped for
# /usr/share/man/man1 (cmake/Install.cmake's target mppid-man; tools/package.sh builds it):
#
#   man-page.sh OUT NAME VERSION DESCRIPTION COMMAND...
#
# COMMAND... runs the program (the built binary, through qemu-user in the cross build; the
# build's Python for the Python programs); it is called NAME here, so the page says NAME.
set -eu
[ $# -ge 5 ] || { echo "usage: man-page.sh OUT NAME VERSION DESCRIPTION COMMAND..." >&2; exit 2; }
out="$1" name="$2" version="$3" description="$4"
shift 4
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
{
  echo '#!/bin/sh'
  printf 'exec'
  for a in "$@"; do printf " '%s'" "$a"; done
  echo ' "$@"'
} > "$tmp/$name"
chmod 755 "$tmp/$name"
help2man --no-info --no-discard-stderr --section=1 --source="mppid $version" \
  --manual="mppid manual" --version-string="$version" --name="$description" \
  --output="$tmp/$name.1" "$tmp/$name"
gzip -9n -c "$tmp/$name.1" > "$out"
