# Sourced by the scripts that install what they need (scripts/package,
# scripts/arm64-equivalence, .ci/vcan/setup, .ci/systemd/setup).
#
# apt_install_missing WHO PKG...: installs those of PKG... that dpkg does not list as
# installed, with apt-get (as root, else through sudo; without a terminal, sudo -n
# fails rather than waits for a password). Says so on stderr as WHO; apt-get's output
# goes to stderr too: some callers print their result on stdout.
apt_install_missing() {
    local who=$1 p
    shift
    local missing=() sudo=()
    if [ "$(id -u)" != 0 ]; then
        if [ -t 0 ]; then sudo=(sudo); else sudo=(sudo -n); fi
    fi
    for p in "$@"; do
        dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q 'ok installed$' || missing+=("$p")
    done
    [ ${#missing[@]} -gt 0 ] || return 0
    echo "$who: installing ${missing[*]}" >&2
    "${sudo[@]}" env DEBIAN_FRONTEND=noninteractive apt-get update -qq >&2
    "${sudo[@]}" env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "${missing[@]}" >&2
}
