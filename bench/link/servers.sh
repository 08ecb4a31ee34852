# Servers on loopback for the link benchmarks (link_bench.sh, scene_coldload.sh): sourced, not
# run. The caller keeps a `pids` array of what to stop on exit.

# port_of FILE: waits for "listening on ...:PORT" as the file's first line (tessera serve,
# tessera-link-proxy) and prints PORT.
port_of() {
  local line="" i
  for ((i = 0; i < 200; ++i)); do
    line=$(head -1 "$1" 2>/dev/null || true)
    [[ $line == listening\ on* ]] && { echo "${line##*:}"; return 0; }
    sleep 0.05
  done
  echo "${0##*/}: no 'listening on' line in $1" >&2; return 1
}

# start_nginx RUN ROOT PROBE [DIRECTIVES]: nginx serving ROOT on a free loopback port, its
# configuration and logs under RUN (access log RUN/nginx-access.log), DIRECTIVES added to the
# server block; waits until PROBE (a path under ROOT) answers and sets NGINX_PORT. For TLS:
# NGINX_LISTEN_FLAGS="ssl http2", NGINX_SCHEME=https and the certificate in DIRECTIVES.
start_nginx() {
  local run=$1 root=$2 probe=$3 directives=${4:-} i
  NGINX_PORT=$(python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])')
  mkdir -p "$run/nginx"
  cat > "$run/nginx/nginx.conf" <<EOF
daemon off;
worker_processes 2;
pid $run/nginx/nginx.pid;
error_log $run/nginx/error.log;
events { worker_connections 1024; }
http {
  include /etc/nginx/mime.types;
  access_log $run/nginx-access.log;
  client_body_temp_path $run/nginx; proxy_temp_path $run/nginx; fastcgi_temp_path $run/nginx;
  uwsgi_temp_path $run/nginx; scgi_temp_path $run/nginx;
  sendfile on; tcp_nopush on; keepalive_requests 10000;
  types { application/octet-stream tess; application/xml dzi; }
  server {
    listen 127.0.0.1:$NGINX_PORT ${NGINX_LISTEN_FLAGS:-};
    root $root;
    $directives
  }
}
EOF
  nginx -c "$run/nginx/nginx.conf" -p "$run/nginx" &
  pids+=($!)
  for ((i = 0; i < 200; ++i)); do
    curl -skf -o /dev/null "${NGINX_SCHEME:-http}://127.0.0.1:$NGINX_PORT/$probe" && return 0
    sleep 0.05
  done
  echo "${0##*/}: nginx did not answer on port $NGINX_PORT" >&2; return 1
}

# proxy_carried FILE: the bytes tessera-link-proxy carried to clients (its exit line).
proxy_carried() {
  sed -n 's/^carried \([0-9]*\) B to the server and \([0-9]*\) B to clients.*/\2/p' "$1"
}
