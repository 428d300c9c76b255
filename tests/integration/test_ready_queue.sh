#!/usr/bin/env bash
# GET /v1/health/ready is what a load balancer's health check asks
# (docker/haproxy): it answers 503 while the job queue is full, so a full
# replica leaves the balancer's ring, and 200 again once there is room.
# A daemon with --max-queue 1 and one render thread: job A runs, job B
# waits (queue full: 503 naming the queue), both cancelled: 200. Also:
# GET /v1 names the process's "instance" (16 hex digits), different for two
# daemons (raysweep sweep --spread tells replicas apart by it), and the
# first job ids of two daemons differ (a request rerouted to another
# replica must not find a job of the same id there).
name=test_ready_queue
source "$(dirname "$0")/../support/shtest.sh"
need_bins raysweepd
need_cmd curl "to talk to the daemon"
start_daemon "$tmp/d" --threads 1 --max-queue 1
port=$started_port
[ -n "$port" ] || { bad "the daemon did not start: $(cat "$tmp/d/log")"; finish; }
url="http://127.0.0.1:$port"
ready() { curl -s -o "$tmp/ready" -w '%{http_code}' "$url/v1/health/ready"; }
[ "$(ready)" = 200 ] && ok || bad "an idle daemon is not ready: $(cat "$tmp/ready")"
scene=$(curl -sf -X POST -H 'Content-Type: application/json' --data-binary @"$root/proto/examples/hdistant_lambertian.json" "$url/v1/scenes" |
  python3 -c 'import json,sys; print(json.load(sys.stdin)["id"])')
long='{"contexts": [{"id": "a", "wavelength": 550}], "defaults": {"spp": 4000000}}'
job() { curl -sf -X POST -H 'Content-Type: application/json' --data "$long" "$url/v1/scenes/$scene/jobs" |
  python3 -c 'import json,sys; print(json.load(sys.stdin)["id"])'; }
a=$(job)
for _ in $(seq 100); do # A leaves the queue when the worker takes it
  curl -s "$url/v1/jobs/$a" | grep -q '"running"' && break
  sleep 0.05
done
[ "$(ready)" = 200 ] && ok || bad "one running job, empty queue: not ready: $(cat "$tmp/ready")"
b=$(job)
code=$(ready)
if [ "$code" = 503 ] && grep -q "queue is full" "$tmp/ready"; then ok; else bad "queue full: ready answered $code: $(cat "$tmp/ready")"; fi
curl -s -o /dev/null -X POST "$url/v1/jobs/$b:cancel"
curl -s -o /dev/null -X POST "$url/v1/jobs/$a:cancel"
code=0
for _ in $(seq 200); do
  code=$(ready)
  [ "$code" = 200 ] && break
  sleep 0.05
done
[ "$code" = 200 ] && ok || bad "after cancelling both jobs ready answers $code: $(cat "$tmp/ready")"
start_daemon "$tmp/e" --threads 1
i1=$(curl -s "$url/v1" | python3 -c 'import json,sys; print(json.load(sys.stdin).get("instance", ""))')
i2=$(curl -s "http://127.0.0.1:$started_port/v1" | python3 -c 'import json,sys; print(json.load(sys.stdin).get("instance", ""))')
j2=$(curl -sf -X POST -H 'Content-Type: application/json' --data-binary @"$root/proto/examples/hdistant_lambertian.json" "http://127.0.0.1:$started_port/v1/scenes" >/dev/null &&
  curl -sf -X POST -H 'Content-Type: application/json' --data '{"contexts": [{"id": "a", "wavelength": 550}], "defaults": {"spp": 1}}' \
    "http://127.0.0.1:$started_port/v1/scenes/$scene/jobs" | python3 -c 'import json,sys; print(json.load(sys.stdin)["id"])')
if [ -n "$a" ] && [ -n "$j2" ] && [ "$a" != "$j2" ]; then ok; else bad "the first jobs of two daemons: '$a' and '$j2': want two different ids"; fi
if [[ $i1 =~ ^[0-9a-f]{16}$ ]] && [[ $i2 =~ ^[0-9a-f]{16}$ ]] && [ "$i1" != "$i2" ]; then ok; else bad "instances '$i1' and '$i2': want two different 16-hex-digit ids"; fi
finish
