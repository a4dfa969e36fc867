# motionaug service images: one build stage, two runtime targets.
#
#   docker build --target coordinator -t motionaug-coordinator .
#   docker build --target worker      -t motionaug-worker .
#
# docker-compose.yml builds both. The binaries need no TLS or system libraries
# beyond glibc (Postgres and Redis are reached over plain TCP inside the cluster).

FROM rust:1.95-slim-bookworm AS build
# Node.js and npm bundle the coordinator's viewer page (crates/viewer/build.rs).
RUN apt-get update \
 && apt-get install -y --no-install-recommends nodejs npm \
 && rm -rf /var/lib/apt/lists/*
WORKDIR /src
COPY . .
RUN cargo build --release -p motionaug-coordinator -p motionaug-worker \
 && cp target/release/motionaug-coordinator target/release/motionaug-worker /usr/local/bin/

FROM debian:bookworm-slim AS runtime
RUN useradd --system --uid 10001 --no-create-home motionaug
USER 10001

FROM runtime AS coordinator
COPY --from=build /usr/local/bin/motionaug-coordinator /usr/local/bin/motionaug-coordinator
ENV MOTIONAUG_LISTEN=0.0.0.0:8080
EXPOSE 8080
ENTRYPOINT ["motionaug-coordinator"]
CMD ["serve"]

FROM runtime AS worker
COPY --from=build /usr/local/bin/motionaug-worker /usr/local/bin/motionaug-worker
ENTRYPOINT ["motionaug-worker"]
