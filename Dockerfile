# syntax=docker/dockerfile:1
# relume serve in a container (docs/deploy.md). Two stages: the build, then a slim runtime with
# the Vulkan loader and Mesa's lavapipe, so the container renders on the CPU where no GPU is
# given. With the NVIDIA container runtime (nvidia-container-toolkit, `--gpus all` or the
# Kubernetes device plugin's `nvidia.com/gpu`), NVIDIA_DRIVER_CAPABILITIES=graphics makes the
# runtime mount the driver's Vulkan ICD into the container, and wgpu then prefers the GPU (a
# discrete adapter sorts before lavapipe; `--adapters` chooses among several).

FROM rust:1.88-bookworm AS build
WORKDIR /src
COPY Cargo.toml Cargo.lock build.rs ./
COPY proto proto
COPY src src
COPY assets assets
COPY fixtures fixtures
RUN cargo build --release --locked --bin relume

FROM debian:bookworm-slim
RUN apt-get update \
    && apt-get install -y --no-install-recommends libvulkan1 mesa-vulkan-drivers ca-certificates curl \
    && rm -rf /var/lib/apt/lists/* \
    && useradd --system --uid 10001 --home-dir /srv/relume relume \
    && mkdir -p /srv/relume/assets /srv/relume/scenes \
    && chown -R relume /srv/relume
COPY --from=build /src/target/release/relume /usr/local/bin/relume
COPY --from=build /src/fixtures /srv/relume/assets/fixtures
ENV NVIDIA_DRIVER_CAPABILITIES=graphics,compute,utility \
    NVIDIA_VISIBLE_DEVICES=all \
    XDG_RUNTIME_DIR=/tmp \
    RELUME_ADDR=0.0.0.0:8080 \
    RELUME_ASSETS=/srv/relume/assets \
    RELUME_SCENE_STORE=/srv/relume/scenes \
    RELUME_DRAIN_DELAY_SECONDS=5 \
    RELUME_SHUTDOWN_GRACE_SECONDS=30
USER 10001
WORKDIR /srv/relume
EXPOSE 8080
HEALTHCHECK --interval=10s --timeout=3s --retries=3 CMD curl -fsS http://127.0.0.1:8080/healthz >/dev/null || exit 1
ENTRYPOINT ["/usr/local/bin/relume"]
CMD ["serve"]
