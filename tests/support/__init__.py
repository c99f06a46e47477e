"""Test support shared by tests/ and benchmarks/: readiness waits, loopback processes, recording sinks, the lossy relay, the MAVProxy chain, fuzzing, pymavlink reference decoding."""
