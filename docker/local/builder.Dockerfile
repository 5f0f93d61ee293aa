# The builder stage's image where no image registry is reachable (scripts/docker_smoke.sh):
# Debian's build tools on the local Debian base, and a Rust toolchain copied from the host
# (rust.tar: the toolchain's bin/ and lib/, unpacked into /usr/local/rust), trusting the
# host's local certificate authorities (ca/).
ARG BASE_IMAGE=l3-local/debian:bookworm
FROM ${BASE_IMAGE}
RUN apt-get update \
    && apt-get install -y --no-install-recommends build-essential pkg-config ca-certificates \
    && rm -rf /var/lib/apt/lists/*
ADD rust.tar /usr/local/rust/
# the host's local certificate authorities, if any (ca/*.crt)
COPY ca/ /usr/local/share/ca-certificates/
RUN update-ca-certificates >/dev/null
ENV CARGO_HOME=/usr/local/cargo \
    PATH=/usr/local/rust/bin:/usr/local/cargo/bin:/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin
RUN rustc --version && cargo --version
