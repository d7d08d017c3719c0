#!/bin/sh
# Access control for the compose deployment, made once (kept across restarts) in $SECRETS_DIR:
#   credentials   every user:password line: the router's dictionary (coordinator and worker)
#   coordinator   the coordinator's own line        worker   the workers' line (copy it to remote workers)
#   router.json5  the Zenoh router's config: user/password authentication against `credentials`
# Passwords come from openssl's random generator. Files are private to their owner (uid 1000 = the
# spinefarm user of the service images).
set -eu
d="${SECRETS_DIR:-/secrets}"
owner="${SECRETS_OWNER:-1000}"
umask 077
mkdir -p "$d"
if [ ! -s "$d/credentials" ]; then
  printf 'coordinator:%s\nworker:%s\n' "$(openssl rand -hex 24)" "$(openssl rand -hex 24)" > "$d/credentials.tmp"
  mv "$d/credentials.tmp" "$d/credentials"
fi
sed -n 1p "$d/credentials" > "$d/coordinator"
sed -n 2p "$d/credentials" > "$d/worker"
cat > "$d/router.json5" <<JSON5
{
  // made by deploy/make-credentials.sh: every session must authenticate with a line of the dictionary
  transport: { auth: { usrpwd: { dictionary_file: "$d/credentials" } } },
}
JSON5
chown "$owner" "$d/coordinator" "$d/worker" 2>/dev/null || true
echo "credentials in $d: users $(cut -d: -f1 "$d/credentials" | tr '\n' ' ')"
