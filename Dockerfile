# syntax=docker/dockerfile:1
# Build: docker build -t flatmesh .
# Run:   docker run -p 8080:8080 -v flatmesh-data:/data flatmesh
FROM rust:1-slim-bookworm AS build
WORKDIR /src
# Dependencies first, so that source edits do not rebuild them.
COPY Cargo.toml Cargo.lock ./
RUN mkdir -p src benches && echo 'fn main() {}' > src/main.rs && touch src/lib.rs \
    && for b in $(awk '/^\[\[bench\]\]/{b=1; next} b && /^name/{gsub(/"/, "", $3); print $3; b=0}' Cargo.toml); \
       do echo 'fn main() {}' > benches/$b.rs; done \
    && cargo build --release --locked --bin flatmesh || true
COPY . .
RUN touch src/main.rs src/lib.rs && cargo build --release --locked --bin flatmesh \
    && strip target/release/flatmesh

FROM debian:bookworm-slim
RUN useradd --system --uid 10001 --home-dir /data --shell /usr/sbin/nologin flatmesh \
    && mkdir -p /data && chown flatmesh /data
COPY --from=build /src/target/release/flatmesh /usr/local/bin/flatmesh
USER flatmesh
VOLUME /data
ENV FLATMESH_BIND=0.0.0.0:8080 \
    FLATMESH_DATA_DIR=/data
EXPOSE 8080
HEALTHCHECK --interval=30s --timeout=5s --start-period=5s --retries=3 \
    CMD ["flatmesh", "client", "--server", "http://127.0.0.1:8080", "health"]
ENTRYPOINT ["flatmesh"]
CMD ["serve"]
