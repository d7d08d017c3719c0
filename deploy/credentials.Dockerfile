# The compose init service that makes the deployment's credentials with openssl from Debian.
FROM debian:bookworm-slim
RUN apt-get update \
 && apt-get install -y --no-install-recommends openssl \
 && rm -rf /var/lib/apt/lists/*
COPY deploy/make-credentials.sh /usr/local/bin/make-credentials
ENTRYPOINT ["/bin/sh", "/usr/local/bin/make-credentials"]
