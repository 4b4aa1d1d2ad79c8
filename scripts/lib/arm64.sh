# Sourced by the scripts that run arm64 binaries on an amd64 host
# (scripts/arm64-equivalence, scripts/bare-debian-install, scripts/gateway-footprint,
# scripts/package).

# arm64_binfmt: registers Debian's qemu-aarch64-static with the kernel's binfmt_misc
# (qemu-user-static installed), as systemd-binfmt does at boot on a Debian host: arm64
# executables then run through qemu, also the processes they start (the estimator)
# and those in a chroot (the entry's F flag: the kernel keeps qemu open).
arm64_binfmt() {
    local sudo=()
    [ "$(id -u)" = 0 ] || sudo=(sudo)
    [ ! -e /proc/sys/fs/binfmt_misc/qemu-aarch64 ] || return 0
    [ -e /proc/sys/fs/binfmt_misc/register ] ||
        "${sudo[@]}" mount -t binfmt_misc binfmt_misc /proc/sys/fs/binfmt_misc
    "${sudo[@]}" sh -c 'cat /usr/lib/binfmt.d/qemu-aarch64.conf >/proc/sys/fs/binfmt_misc/register'
}

# arm64_foreign_architecture: adds arm64 to dpkg's architectures (multiarch), so that
# apt installs arm64 libraries beside the host's; the package lists are read again.
arm64_foreign_architecture() {
    local sudo=()
    [ "$(id -u)" = 0 ] || sudo=(sudo)
    dpkg --print-foreign-architectures | grep -qx arm64 && return 0
    "${sudo[@]}" dpkg --add-architecture arm64
    "${sudo[@]}" apt-get update -qq
}
