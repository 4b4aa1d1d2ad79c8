# Sourced by the scripts that build probebridge with Debian 12's own Rust (rustc-web:
# Debian's rustc is 1.63, the project needs 1.89): scripts/package and CI's arm64 step
# (.ci/arm64-beside). arm64 is cross-compiled against Debian's arm64 standard library
# (multiarch) with gcc-aarch64-linux-gnu, and links Debian's libsqlite3 of its
# architecture. Run from the clone's root.

# debian_rust_install WHO ARCH...: installs what a build for each ARCH needs (arm64:
# also as dpkg's foreign architecture).
debian_rust_install() {
    local who=$1
    shift
    local need=(rustc-web cargo-web pkgconf libsqlite3-dev)
    if [[ " $* " == *" arm64 "* ]]; then
        source scripts/lib/arm64.sh
        arm64_foreign_architecture
        need+=(gcc-aarch64-linux-gnu libc6-dev-arm64-cross libstd-rust-web-dev:arm64 libc6:arm64
            libgcc-s1:arm64 libsqlite3-dev:arm64)
    fi
    source scripts/lib/apt.sh
    apt_install_missing "$who" "${need[@]}"
}

# debian_rust_build ARCH PROFILE TARGET_DIR [CARGO ARGS...]: builds the probebridge
# binary for ARCH (amd64 or arm64) with the cargo profile PROFILE into TARGET_DIR
# (cargo's output on stderr); prints the binary's path.
debian_rust_build() {
    local arch=$1 profile=$2 dir=$3 triple
    shift 3
    case "$arch" in
        amd64) triple=x86_64-unknown-linux-gnu ;;
        arm64) triple=aarch64-unknown-linux-gnu ;;
        *) echo "debian_rust_build: $arch: amd64 or arm64" >&2; return 2 ;;
    esac
    # Debian's toolchain, not rustup's (which may come first in PATH).
    RUSTC=/usr/bin/rustc RUSTDOC=/usr/bin/rustdoc \
        CARGO_TARGET_AARCH64_UNKNOWN_LINUX_GNU_LINKER=aarch64-linux-gnu-gcc \
        CC_aarch64_unknown_linux_gnu=aarch64-linux-gnu-gcc \
        AR_aarch64_unknown_linux_gnu=aarch64-linux-gnu-ar \
        PKG_CONFIG_ALLOW_CROSS=1 \
        PKG_CONFIG_LIBDIR_aarch64_unknown_linux_gnu=/usr/lib/aarch64-linux-gnu/pkgconfig:/usr/share/pkgconfig \
        /usr/bin/cargo build --profile "$profile" --locked -p probebridge --no-default-features \
        --target "$triple" --target-dir "$dir" "$@" >&2 || return
    echo "$dir/$triple/$profile/probebridge"
}
