# Sourced by setup_env.sh and setup_cross.sh: installs the Debian packages of a list
# that are not installed yet, quietly, with one line naming them (nothing when all
# are there). Needs root when something is missing.
#
#   apt_missing TAG PACKAGE...     (TAG: the caller's name in the log line)
apt_missing() {
  local tag=$1 p out
  shift
  local missing=()
  for p in "$@"; do
    dpkg -s "$p" >/dev/null 2>&1 || missing+=("$p")
  done
  [ ${#missing[@]} -gt 0 ] || return 0
  echo "[$tag] installing Debian packages: ${missing[*]}" >&2
  out=$( { DEBIAN_FRONTEND=noninteractive apt-get update -qq \
    && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "${missing[@]}"; } 2>&1) \
    || { echo "$out" >&2; return 1; }
}
