#!/usr/bin/env bash
# make test-cluster: docker/Dockerfile, docker/compose/compose.yaml,
# docker/k8s/*.yaml and docker/raysweepd-drain checked against the real
# daemon (tests/cluster/containers_check.py says how; no Docker engine or
# Kubernetes is needed).
name=test_containers
. "$(dirname "$0")/../support/shtest.sh"
need_bins raysweepd raysweep
need_cmd python3 "(make deps-cluster)"
need_cmd haproxy "to check the HAProxy configurations (make deps-cluster)"
python3 -c 'import yaml' 2>/dev/null || { bad "python3-yaml is needed (make deps-cluster)"; finish; }
RSW_BIN_DIR=$bin exec python3 "$root/tests/cluster/containers_check.py"
