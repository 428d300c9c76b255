#!/usr/bin/env python3
"""Write a HAProxy or nginx configuration for R raysweepd replicas.

    docker/lb/gen.py haproxy|nginx --listen HOST:PORT --replica HOST:PORT [--replica ...]
                     [--run-dir DIR] [--check-interval-ms N] [-o FILE]

Routing: consistent hashing on the X-Raysweep-Shard request header, which
libraysweep sends on every request of a shard (rsw_client_opts.route_key,
`raysweep sweep --spread K`). Every request of one shard -- scene push,
blob upload, job submit, events, results, films -- hashes to the same
replica, so replica-local job ids stay valid and a scene stays warm on few
replicas; the balancer keeps no state. When a replica leaves the ring only
its keys move (consistent hashing), and the client resubmits what it lost
under a new key.

A request without the header (or with an empty one) is routed as the key
"-": all such requests reach one replica, so a client that sends no key
(curl, the Python package, `raysweep sweep` without --spread) finds the
scene it pushed and the job it submitted. Both balancers fall back to
round-robin for a missing key (HAProxy's documented fallback for hdr();
nginx's hash for an empty key), which sent a push and the job that
followed it to different replicas: 404.

- HAProxy: `balance hdr(X-Raysweep-Shard)` with `hash-type consistent`
  (HAProxy configuration manual, "balance" and "hash-type"), the key "-"
  set first where none came (`http-request set-header`); active health
  checks on GET /v1/health/ready, which answers 503 while the replica is
  shutting down or its job queue is full, so such a replica drops out.
- nginx: `hash $raysweep_shard consistent;` in the upstream (nginx
  ngx_http_upstream_module, "hash", ketama), $raysweep_shard the header
  or "-" (a `map`). nginx open source has no
  active health checks (`health_check` is NGINX Plus only): a replica is
  taken out passively (max_fails/fail_timeout) after connection errors
  and 502/503/504 answers, and proxy_next_upstream sends an idempotent
  request that met one to the next replica on the ring.

The shipped docker/haproxy/haproxy.cfg and docker/nginx/nginx.conf are this
script's output for three replicas raysweep-1..3:8350 (make test-cluster
checks they are current).
"""
import argparse
import sys

HEADER = "X-Raysweep-Shard"


def hostport(s):
    host, sep, port = s.rpartition(":")
    if not sep or not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise argparse.ArgumentTypeError(f"'{s}' is not HOST:PORT")
    return s


def haproxy(a):
    servers = "\n".join(
        f"    server r{i + 1} {r} check" for i, r in enumerate(a.replica))
    return f"""# raysweep: HAProxy in front of {len(a.replica)} raysweepd replicas (docker/lb/gen.py haproxy).
# Consistent hashing on the {HEADER} header: every request of one shard
# (scene push, blob upload, job submit, events, results) reaches one replica.
global
    maxconn 4096

defaults
    mode http
    timeout connect 5s
    timeout client 1h
    timeout server 1h
    timeout tunnel 1h
    timeout http-request 30s
    # A replica that refuses the connection: try again, then another one.
    retries 2
    option redispatch 1

frontend raysweep
    bind {a.listen}
    default_backend replicas

backend replicas
    # No key (or an empty one): the key "-", one replica for all such
    # requests (hdr() would balance them round-robin: a scene pushed to
    # one replica, its job submitted to another).
    http-request set-header {HEADER} - unless {{ req.hdr({HEADER}) -m len 1: }}
    balance hdr({HEADER})
    hash-type consistent
    # Ready = not shutting down and the job queue not full (raysweepd).
    option httpchk GET /v1/health/ready
    http-check expect status 200
    # init-addr: start even when a replica name does not resolve yet (compose, Kubernetes).
    default-server init-addr last,libc,none inter {a.check_interval_ms}ms fastinter {a.check_interval_ms}ms downinter {a.check_interval_ms}ms fall 2 rise 2
{servers}
"""


def nginx(a):
    servers = "\n".join(
        f"        server {r} max_fails=1 fail_timeout=5s;" for r in a.replica)
    d = a.run_dir
    return f"""# raysweep: nginx in front of {len(a.replica)} raysweepd replicas (docker/lb/gen.py nginx).
# Consistent hashing on the {HEADER} header: every request of one shard
# (scene push, blob upload, job submit, events, results) reaches one replica.
daemon off;
worker_processes 1;
pid {d}/nginx.pid;
error_log {d}/error.log warn;

events {{
    worker_connections 1024;
}}

http {{
    access_log off;
    client_body_temp_path {d}/client_body;
    proxy_temp_path {d}/proxy;
    fastcgi_temp_path {d}/fastcgi;
    uwsgi_temp_path {d}/uwsgi;
    scgi_temp_path {d}/scgi;

    # No key (or an empty one): the key "-", one replica for all such
    # requests (an empty key would be balanced round-robin: a scene pushed
    # to one replica, its job submitted to another).
    map $http_x_raysweep_shard $raysweep_shard {{
        "" "-";
        default $http_x_raysweep_shard;
    }}

    upstream raysweep {{
        hash $raysweep_shard consistent;
{servers}
        keepalive 32;
    }}

    server {{
        listen {a.listen};
        # Blobs (meshes, textures) are uploaded through the balancer.
        client_max_body_size 0;
        location / {{
            proxy_pass http://raysweep;
            proxy_http_version 1.1;
            proxy_set_header Connection "";
            proxy_set_header Host $host;
            # Job events are a server-sent event stream: no buffering, long reads.
            proxy_buffering off;
            proxy_request_buffering off;
            proxy_read_timeout 1h;
            proxy_send_timeout 1h;
            proxy_next_upstream error timeout http_502 http_503 http_504;
            proxy_next_upstream_tries 2;
        }}
    }}
}}
"""


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("kind", choices=["haproxy", "nginx"])
    p.add_argument("--listen", type=hostport, required=True)
    p.add_argument("--replica", type=hostport, action="append", required=True)
    p.add_argument("--run-dir", default="/tmp/raysweep-nginx",
                   help="nginx: pid, error log and temp files (writable by the user nginx runs as)")
    p.add_argument("--check-interval-ms", type=int, default=1000,
                   help="HAProxy: health check interval (default 1000)")
    p.add_argument("-o", metavar="FILE", help="write here (default stdout)")
    a = p.parse_args()
    text = haproxy(a) if a.kind == "haproxy" else nginx(a)
    if a.o:
        with open(a.o, "w") as f:
            f.write(text)
    else:
        sys.stdout.write(text)


if __name__ == "__main__":
    main()
