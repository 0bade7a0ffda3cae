#!/bin/bash
# Remote round trip (null-small x1) and CartPole x1024 remote throughput, `envhub bench --hub`,
# for two builds back to back on one machine (before and after a change):
#   scripts/bench_remote_pair.sh /path/to/checkout-before /path/to/checkout-after
# Each root needs its installed binaries (python/envhub/bin/envhub). The client reads
# the hub's loopback credential from the same ENVHUB_LOCAL_HUBS folder (docs/design/security.md).
set -u
i=0
for root in "$@"; do
  i=$((i + 1)); side=b$i
  bin=$root/python/envhub/bin/envhub
  port=$((17500 + RANDOM % 400))
  ENVHUB_TEST_ADAPTERS=1 ENVHUB_NAMESPACE=benchhub_${side}_ ENVHUB_MULTICAST=0 ENVHUB_LOCAL_HUBS=/tmp/bench-local-$side \
    $bin --registry @default --registry $root/configs/bench/data_plane.yaml \
    serve --name bench$side --listen tcp/127.0.0.1:$port --socket /tmp/bench-$side.sock > /tmp/bench-hub-$side.log 2>&1 &
  hub=$!
  sleep 3
  for args in "null-small --num-envs 1" "gym-cartpole --num-envs 1024"; do
    echo "== $side $args"
    ENVHUB_TEST_ADAPTERS=1 ENVHUB_MULTICAST=0 ENVHUB_LOCAL_HUBS=/tmp/bench-local-$side timeout 120 $bin --registry @default --registry $root/configs/bench/data_plane.yaml \
      --connect tcp/127.0.0.1:$port bench $args --workers 1 --hub bench$side --json 2>&1 | tail -c 3000
  done
  kill $hub; wait $hub 2>/dev/null
done
