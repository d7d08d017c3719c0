# The compose init service that makes the deployment's credentials with openssl from Debian.
# BASE: any Debian image; openssl is installed only when the base lacks it (the offline base has it).
ARG BASE=debian:bookworm-slim
FROM ${BASE}
RUN command -v openssl >/dev/null || (apt-get update \
 && apt-get install -y --no-install-recommends openssl \
 && rm -rf /var/lib/apt/lists/*)
COPY deploy/make-credentials.sh /usr/local/bin/make-credentials
ENTRYPOINT ["/bin/sh", "/usr/local/bin/make-credentials"]
