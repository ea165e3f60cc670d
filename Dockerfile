# Multi-stage: build every binary with the Rust toolchain, run them from a slim Debian image.
FROM rust:1-bookworm AS build
WORKDIR /src
COPY . .
RUN cargo build --release --locked -p radcast-server -p radcast-client -p radcast-cli

FROM debian:bookworm-slim
RUN useradd --system --home /srv/radcast radcast \
 && mkdir -p /srv/radcast/cache /renders \
 && chown radcast /srv/radcast/cache /renders
COPY --from=build /src/target/release/radcast-server /src/target/release/radcast-client /src/target/release/radcast /usr/local/bin/
COPY scenes /srv/radcast/scenes
WORKDIR /srv/radcast
USER radcast
ENV RADCAST_ADDR=0.0.0.0:8080 RADCAST_CACHE_DIR=/srv/radcast/cache
EXPOSE 8080
CMD ["radcast-server"]
