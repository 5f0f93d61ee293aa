#!/usr/bin/env bash
# Makes the local images docker/Dockerfile and the smoke's topology need where no image
# registry is reachable (FROM rust:…, debian:…, postgres, nginx cannot be pulled):
#   l3-local/debian:bookworm       debootstrap --variant=minbase bookworm, slimmed like bookworm-slim
#   l3-local/rust:1.95-bookworm    that + Debian's build tools + the host's Rust toolchain
#   l3-local/postgres:15           that + Debian's postgresql-15 (docker/local/postgres.Dockerfile)
#   l3-local/nginx:bookworm        that + Debian's nginx (docker/local/nginx.Dockerfile)
# An image that exists is kept (L3_REBUILD_LOCAL_IMAGES=1 remakes them all).
# Needs root, debootstrap, docker, a reachable Debian mirror and a rustup toolchain on the host.
# Usage: scripts/docker_local_images.sh
set -euo pipefail

here=$(cd "$(dirname "$0")/.." && pwd)
mirror=${DEBIAN_MIRROR:-http://deb.debian.org/debian}
toolchain=${RUST_TOOLCHAIN:-1.95.0}
base=l3-local/debian:bookworm
builder=l3-local/rust:${toolchain%.*}-bookworm
postgres=l3-local/postgres:15
nginx=l3-local/nginx:bookworm

have() { [ "${L3_REBUILD_LOCAL_IMAGES:-0}" != 1 ] && docker image inspect "$1" >/dev/null 2>&1; }

make_base() {
    local root
    root=$(mktemp -d /var/tmp/l3-rootfs.XXXXXX)
    debootstrap --variant=minbase bookworm "$root" "$mirror" >/dev/null
    cat > "$root/etc/apt/sources.list" <<SOURCES
deb $mirror bookworm main
deb $mirror bookworm-updates main
deb http://deb.debian.org/debian-security bookworm-security main
SOURCES
    # as debian:bookworm-slim: no documentation, manuals or translations, now or later
    cat > "$root/etc/dpkg/dpkg.cfg.d/docker-slim" <<'SLIM'
path-exclude /usr/share/doc/*
path-include /usr/share/doc/*/copyright
path-exclude /usr/share/man/*
path-exclude /usr/share/info/*
path-exclude /usr/share/locale/*
path-include /usr/share/locale/locale.alias
SLIM
    # and, as there, apt keeps no package files nor caches in the image
    cat > "$root/etc/apt/apt.conf.d/docker-clean" <<'CLEAN'
DPkg::Post-Invoke { "rm -f /var/cache/apt/archives/*.deb /var/cache/apt/archives/partial/*.deb /var/cache/apt/*.bin || true"; };
APT::Update::Post-Invoke { "rm -f /var/cache/apt/archives/*.deb /var/cache/apt/archives/partial/*.deb /var/cache/apt/*.bin || true"; };
Dir::Cache::pkgcache "";
Dir::Cache::srcpkgcache "";
CLEAN
    echo 'Acquire::Languages "none";' > "$root/etc/apt/apt.conf.d/docker-no-languages"
    find "$root/usr/share/doc" -type f ! -name copyright -delete
    rm -rf "$root"/usr/share/man/* "$root"/usr/share/info/* "$root"/var/cache/apt/archives/*.deb \
        "$root"/var/cache/apt/*.bin \
        "$root"/var/lib/apt/lists/* "$root"/var/log/*.log
    find "$root/usr/share/locale" -mindepth 1 -maxdepth 1 ! -name locale.alias -exec rm -rf {} +
    tar -C "$root" -c . | docker import -c 'ENV LANG=C.UTF-8' -c 'CMD ["bash"]' - "$base" >/dev/null
    rm -rf "$root"
}

make_builder() {
    local ctx sysroot
    ctx=$(mktemp -d /var/tmp/l3-builder.XXXXXX)
    sysroot=$(rustup run "$toolchain" rustc --print sysroot)
    # the compiler, cargo and the standard library; not the documentation
    tar -C "$sysroot" -cf "$ctx/rust.tar" bin lib
    # the host's own certificate authorities (e.g. a TLS-inspecting proxy's), so cargo reaches
    # crates.io from the builder as it does from the host; the runtime image gets none of them
    mkdir -p "$ctx/ca"
    cp /usr/local/share/ca-certificates/*.crt "$ctx/ca/" 2>/dev/null || true
    cp "$here/docker/local/builder.Dockerfile" "$ctx/Dockerfile"
    docker build --network host -q --build-arg BASE_IMAGE="$base" -t "$builder" "$ctx" >/dev/null
    rm -rf "$ctx"
}

make_from_dockerfile() {  # IMAGE DOCKERFILE
    docker build --network host -q --build-arg BASE_IMAGE="$base" -t "$1" \
        -f "$here/docker/local/$2" "$here/docker/local" >/dev/null
}

have "$base" || { echo "making $base (debootstrap)"; make_base; }
have "$builder" || { echo "making $builder"; make_builder; }
have "$postgres" || { echo "making $postgres"; make_from_dockerfile "$postgres" postgres.Dockerfile; }
have "$nginx" || { echo "making $nginx"; make_from_dockerfile "$nginx" nginx.Dockerfile; }
docker image ls --format '{{.Repository}}:{{.Tag}} {{.Size}}' | grep '^l3-local/' | sort
