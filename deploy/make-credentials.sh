#!/bin/sh
# Access control for the compose deployment, made once (kept across restarts) in $SECRETS_DIR with
# openssl: mutual TLS (every link encrypted, every peer shows a certificate of the deployment's CA) and
# Zenoh user/password authentication on top.
#   ca.pem                        the deployment's CA (its key ca.key never leaves this volume)
#   router.pem/.key               the router's certificate (names: router, localhost, $ROUTER_SAN)
#   coordinator.pem/.key, worker.pem/.key    client certificates
#   credentials                   every user:password line: the router's dictionary
#   coordinator, worker           each one's own line (`--credentials`)
#   router.json5, coordinator.json5, worker.json5    Zenoh configs using the files above (`--zenoh-config`)
# ROUTER_SAN adds names the router is reached by from other machines, e.g. "DNS:farm.example,IP:10.0.0.5".
# Files are private to their owner; the coordinator's and workers' files belong to uid $SECRETS_OWNER
# (1000 = the spinefarm user of the service images), the router's to uid $ROUTER_OWNER (0 = root, as the
# official router image runs; 1000 for `spinefarm router` from the service images).
set -eu
d="${SECRETS_DIR:-/secrets}"
owner="${SECRETS_OWNER:-1000}"
router_owner="${ROUTER_OWNER:-0}"
umask 077
mkdir -p "$d"
chmod 755 "$d"  # the services' user must reach its own files; every file stays private
if [ ! -s "$d/credentials" ]; then
  printf 'coordinator:%s\nworker:%s\n' "$(openssl rand -hex 24)" "$(openssl rand -hex 24)" > "$d/credentials.tmp"
  mv "$d/credentials.tmp" "$d/credentials"
fi
sed -n 1p "$d/credentials" > "$d/coordinator"
sed -n 2p "$d/credentials" > "$d/worker"

key() { openssl genpkey -algorithm EC -pkeyopt ec_paramgen_curve:P-256 -out "$1" 2>/dev/null; }
if [ ! -s "$d/ca.pem" ]; then
  key "$d/ca.key"
  openssl req -x509 -new -key "$d/ca.key" -out "$d/ca.pem" -days 3650 -subj "/CN=spinefarm deployment CA"
fi
cert() {  # name subjectAltName
  [ -s "$d/$1.pem" ] && return 0
  key "$d/$1.key"
  openssl req -new -key "$d/$1.key" -out "$d/$1.csr" -subj "/CN=$1"
  printf 'subjectAltName=%s\nextendedKeyUsage=serverAuth,clientAuth\n' "$2" > "$d/$1.ext"
  openssl x509 -req -in "$d/$1.csr" -CA "$d/ca.pem" -CAkey "$d/ca.key" -CAcreateserial -out "$d/$1.pem" \
    -days 825 -extfile "$d/$1.ext" 2>/dev/null
  rm -f "$d/$1.csr" "$d/$1.ext"
}
cert router "DNS:router,DNS:localhost,IP:127.0.0.1${ROUTER_SAN:+,$ROUTER_SAN}"
cert coordinator "DNS:coordinator"
cert worker "DNS:worker"

cat > "$d/router.json5" <<JSON5
{
  // made by deploy/make-credentials.sh: TLS links with client certificates, and user/password
  transport: {
    auth: { usrpwd: { dictionary_file: "$d/credentials" } },
    link: { tls: { root_ca_certificate: "$d/ca.pem", listen_certificate: "$d/router.pem",
                   listen_private_key: "$d/router.key", enable_mtls: true } },
  },
}
JSON5
for who in coordinator worker; do
  cat > "$d/$who.json5" <<JSON5
{
  // made by deploy/make-credentials.sh: connect over TLS with this client certificate
  transport: { link: { tls: { root_ca_certificate: "$d/ca.pem", connect_certificate: "$d/$who.pem",
                              connect_private_key: "$d/$who.key", enable_mtls: true } } },
}
JSON5
  chown "$owner" "$d/$who" "$d/$who.pem" "$d/$who.key" "$d/$who.json5" 2>/dev/null || true
done
chown "$router_owner" "$d/credentials" "$d/router.pem" "$d/router.key" "$d/router.json5" 2>/dev/null || true
chmod 644 "$d/ca.pem"
echo "credentials in $d: users $(cut -d: -f1 "$d/credentials" | tr '\n' ' ')and TLS certificates"
