#!/usr/bin/env bash
# Installs the system packages listed in deploy/packages.txt (Debian 12, as root), or in the
# lists named as arguments (files in deploy/, e.g. ci-packages.txt).
# Used by the README set-up, .ci/run and the Dockerfile, so the three cannot drift.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
lists=("${@:-packages.txt}")
pkgs=$(cd "$here" && cat "${lists[@]}" | grep -v -E '^\s*(#|$)' | tr '\n' ' ')
missing=$(dpkg-query -W -f='${Package} ${Status}\n' $pkgs 2>/dev/null | grep -v 'install ok installed' | cut -d' ' -f1 || true)
# dpkg-query omits unknown packages entirely, so compare counts too.
known=$(dpkg-query -W -f='${Package}\n' $pkgs 2>/dev/null | wc -l || true)
if [ -z "$missing" ] && [ "$known" -eq "$(echo $pkgs | wc -w)" ]; then
  echo "install-deps: all $(echo $pkgs | wc -w) packages already installed"
  exit 0
fi
export DEBIAN_FRONTEND=noninteractive
apt-get update -qq
apt-get install -y -qq --no-install-recommends $pkgs
