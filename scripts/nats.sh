#!/usr/bin/env bash
# Makes sure the tests' NATS is there: `nats-server` installed (Debian's package), and a server
# with JetStream answering at 127.0.0.1:4222 (started here, stored in /var/lib/nats-server or
# a temporary folder, when nothing answers). The fan-out tests also start servers of their own.
set -euo pipefail
sudo_or_not=$([ "$(id -u)" = 0 ] || echo sudo)
if ! command -v nats-server >/dev/null; then
  $sudo_or_not apt-get install -y -q nats-server >/dev/null
fi
answers() { (exec 3<>/dev/tcp/127.0.0.1/4222) 2>/dev/null; }
if ! answers; then
  store=/var/lib/nats-server
  [ -w "$store" ] || store=$(mktemp -d)
  nats-server -a 127.0.0.1 -p 4222 -js -sd "$store" -l "$store/nats-server.log" &
  for _ in $(seq 100); do answers && break; sleep 0.1; done
  answers || { echo "nats-server did not start at 127.0.0.1:4222" >&2; exit 1; }
fi
