# cloudbake-server on Debian 12, built with the same package list and build script as CI.
FROM debian:12 AS build
COPY deploy/ /src/deploy/
RUN bash /src/deploy/install-deps.sh
COPY . /src
RUN BUILD_DIR=/src/build bash /src/deploy/build.sh -DCLOUDBAKE_BUILD_TESTS=OFF \
 && cmake --install /src/build --prefix /opt/cloudbake

FROM debian:12
COPY deploy/packages.txt /tmp/packages.txt
# Runtime needs the shared libraries the build linked; the -dev packages pull them in.
COPY deploy/install-deps.sh /tmp/install-deps.sh
RUN mkdir -p /tmp/deploy && mv /tmp/packages.txt /tmp/install-deps.sh /tmp/deploy/ \
 && bash /tmp/deploy/install-deps.sh && rm -rf /var/lib/apt/lists/* /tmp/deploy
COPY --from=build /opt/cloudbake /opt/cloudbake
ENV PATH=/opt/cloudbake/bin:$PATH
EXPOSE 50051
USER nobody
ENTRYPOINT ["cloudbake-server", "--listen", "0.0.0.0:50051"]
