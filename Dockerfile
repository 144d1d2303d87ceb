# cloudbake-server on Debian 12: built with the same package list and build script as CI, run
# from a stage that holds only the runtime libraries (deploy/runtime-packages.txt), as a non-root
# user, with its state (job store, result cache, assets) on a volume. Tested by
# deploy/container-test.sh; docs/deployment.md. BASE lets a machine without a registry use a
# locally imported Debian 12 (the test builds with --build-arg BASE=localhost/debian:12).
ARG BASE=debian:12

FROM ${BASE} AS build
COPY deploy/packages.txt deploy/install-deps.sh /src/deploy/
RUN bash /src/deploy/install-deps.sh && rm -rf /var/lib/apt/lists/*
COPY . /src
RUN BUILD_DIR=/build bash /src/deploy/build.sh -DCLOUDBAKE_BUILD_TESTS=OFF \
 && cmake --install /build --prefix /opt/cloudbake --strip

FROM ${BASE}
COPY deploy/runtime-packages.txt /tmp/runtime-packages.txt
# Documentation, manuals and translations are never read in the container: dpkg skips them.
RUN printf '%s\n' 'path-exclude=/usr/share/doc/*' 'path-include=/usr/share/doc/*/copyright' \
      'path-exclude=/usr/share/man/*' 'path-exclude=/usr/share/info/*' \
      'path-exclude=/usr/share/locale/*' > /etc/dpkg/dpkg.cfg.d/01-cloudbake-slim \
 && apt-get update -qq \
 && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends \
      $(grep -v -E '^\s*(#|$)' /tmp/runtime-packages.txt) \
 && apt-get clean && rm -rf /var/lib/apt/lists/* /tmp/runtime-packages.txt \
 && groupadd --system --gid 10001 cloudbake \
 && useradd --system --uid 10001 --gid 10001 --home-dir /var/lib/cloudbake --create-home \
      --shell /usr/sbin/nologin cloudbake
COPY --from=build /opt/cloudbake /opt/cloudbake
# Flags come from CLOUDBAKE_* variables (docs/api.md), so a deployment changes them without
# replacing the command. The state folder is the volume: a new container keeps the cache.
ENV PATH=/opt/cloudbake/bin:$PATH \
    HOME=/var/lib/cloudbake \
    CLOUDBAKE_LISTEN=0.0.0.0:50051 \
    CLOUDBAKE_CACHE_DIR=/var/lib/cloudbake
VOLUME /var/lib/cloudbake
WORKDIR /var/lib/cloudbake
# gRPC, and Prometheus metrics when CLOUDBAKE_METRICS_LISTEN is set (e.g. 0.0.0.0:9464).
EXPOSE 50051 9464
USER 10001:10001
ENTRYPOINT ["cloudbake-server"]
