"""Fleet benchmarks: the trend threshold's calibration, and scale (parallel efficiency, memory, queries).

    python -m benchmarks.bench_fleet calibrate [--vehicles 50 --flights 10 --duration 60 --rate 50]
        A simulated fleet (every 5th IMU's N rising 1.5x, the rest healthy) through the whole pipeline
        (tlogs -> fleet analyze on 2 Dask workers -> trend test). Prints the per-test p-value calibration
        of healthy IMUs (fraction below 0.1, 0.01, 0.001 vs nominal), the per-IMU exceedance of evidence
        thresholds for healthy and degrading IMUs, and draws docs/img/fleet_threshold.png.

    python -m benchmarks.bench_fleet scale [--logs 1000 --duration 600 --rate 100 --imus 1]
        N logs of D seconds at R Hz: the same logs analysed in one process (--workers 0 code path) and on
        a LocalCluster of 2 worker processes; prints wall time, logs/s, parallel efficiency
        T1 / (2 T2), each worker's RSS sampled over the run (memory flat in the number of logs?), and
        the time to query one IMU's history from the database. ``--serial-logs K`` times the one-process
        run on the first K logs only (rate extrapolated, said so in the output).

    python -m benchmarks.bench_fleet scale --quick
        40 logs of 60 s at 50 Hz (the run recorded in RESULTS.md).

Each subcommand records its own section of benchmarks/RESULTS.md.

Target: healthy IMUs' p-values at their nominal rates (calibration); parallel efficiency near 1 on 2 workers and
worker memory flat in the number of logs (scale).
"""

from __future__ import annotations

import argparse
import os
import shutil
import sys
import tempfile
import threading
import time

# One BLAS thread per process in both runs: Dask's nanny sets this for its workers, and a one-process run
# with a multi-threaded BLAS would use both cores for part of its time (measured 0.64 CPU s per log with
# threads vs 0.37 without), which makes "one process" a parallel run and the efficiency meaningless.
for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_v] = "1"

import numpy as np  # noqa: E402  (after the thread settings, which numpy reads on import)

from benchmarks import results  # noqa: E402


ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def _warm():
    """Import what the task needs (both runs are timed warm: the imports are a once-per-process cost)."""
    import companion.analysis.stream  # noqa: F401
    import companion.fleet.identity  # noqa: F401
    import companion.fleet.task  # noqa: F401
    import companion.sources.tlog  # noqa: F401
    import scipy.optimize  # noqa: F401
    import scipy.stats  # noqa: F401

    return True


def _analyze(store_path, folder, workers, quiet=True):
    from companion.fleet.discover import discover
    from companion.fleet.dask_runner import FleetProgress, close_client, open_client, plan, run_dask, run_serial
    from companion.fleet.store import FleetStore

    with FleetStore(store_path) as store:
        work = plan(store, discover([folder]))[0]
        prog = FleetProgress(len(work), enabled=not quiet)
        if workers == 0:
            _warm()
            c0 = time.process_time()
            stats = run_serial(store, work, prog)
            stats.cpu_s = time.process_time() - c0
            return stats, None
        client, cluster = open_client(workers)
        client.run(_warm)
        try:
            def cpu():
                import psutil

                t = psutil.Process().cpu_times()
                return t.user + t.system

            w0 = sum(client.run(cpu).values())
            m0 = time.process_time()
            rss = []
            stop = threading.Event()

            def sample():
                while not stop.is_set():
                    try:
                        info = client.scheduler_info()["workers"]
                        rss.append((time.monotonic(), [w["metrics"]["memory"] for w in info.values()]))
                    except Exception:  # noqa: BLE001
                        pass
                    stop.wait(1.0)

            th = threading.Thread(target=sample, daemon=True)
            th.start()
            stats = run_dask(store, work, prog, client)
            stats.cpu_s = sum(client.run(cpu).values()) - w0
            stats.main_cpu_s = time.process_time() - m0
            stop.set()
            th.join()
            return stats, rss
        finally:
            close_client(client, cluster)


def calibrate(args):
    from companion.fleet.fleet_ranking import fleet_trends
    from companion.fleet.synthetic_fleet import simulate_fleet
    from companion.fleet.store import FleetStore
    from companion.fleet.trends import EVIDENCE_THRESHOLD, MIN_RISE

    tmp = tempfile.mkdtemp(prefix="bench_fleet_cal_")
    try:
        n_imus = args.vehicles * args.imus
        deg = n_imus // 5
        t0 = time.time()
        truth = simulate_fleet(os.path.join(tmp, "logs"), args.vehicles, args.flights, args.imus, deg, args.rise,
                               "N", args.duration, args.rate, args.seed)
        t_sim = time.time() - t0
        db = os.path.join(tmp, "fleet.sqlite")
        stats, _ = _analyze(db, os.path.join(tmp, "logs"), args.workers)
        with FleetStore(db, create=False) as store:
            entries = fleet_trends(store)
        sick = {(v["board_id"], i["imu"]) for v in truth["vehicles"] for i in v["imus"] if i["degrading"]}
        null = [e for e in entries if (e["vehicle"], e["imu"]) not in sick]
        bad = [e for e in entries if (e["vehicle"], e["imu"]) in sick]
        pvals = np.array([10 ** t.log10_p for e in null for t in e["_tests"].values()])
        print(f"command: python -m benchmarks.bench_fleet calibrate --vehicles {args.vehicles} --flights "
              f"{args.flights} --imus {args.imus} --duration {args.duration:g} --rate {args.rate:g} --seed {args.seed}")
        print(f"fleet: {len(entries)} IMUs ({len(null)} healthy, {len(bad)} with N x{args.rise:g}), "
              f"{args.flights} flights of {args.duration:g} s at {args.rate:g} Hz; simulated in {t_sim:.0f} s, "
              f"analysed in {stats.elapsed_s:.0f} s ({stats.rate:.2f} logs/s, {args.workers} workers), "
              f"{stats.failed} failed")
        print(f"per-test p-values of healthy IMUs ({pvals.size} tests: axes x N/B/K selected):")
        for a in (0.5, 0.1, 0.01, 0.001):
            k = int((pvals < a).sum())
            sd = np.sqrt(a * (1 - a) / max(pvals.size, 1))
            print(f"  P(p < {a:g}) = {k / max(pvals.size, 1):.4f} (nominal {a:g} +- {sd:.4f})")
        ev0 = np.array([e["evidence"] for e in null])
        ev1 = np.array([e["evidence"] for e in bad])
        grid = np.arange(0.0, 12.01, 0.25)
        print("threshold  healthy IMUs above  (nominal 10^-e)   degrading IMUs above")
        for th in (1, 2, 3, 4, 5, 6):
            print(f"  {th:>4.1f}     {np.mean(ev0 >= th):.4f} ({int((ev0 >= th).sum())}/{ev0.size})   {10.0 ** -th:.0e}"
                  f"            {np.mean(ev1 >= th):.3f} ({int((ev1 >= th).sum())}/{ev1.size})")
        flagged_null = sum(e["flagged"] for e in null)
        flagged_bad = sum(e["flagged"] for e in bad)
        ranked_first = {(e["vehicle"], e["imu"]) for e in entries[:len(bad)]} == sick
        print(f"at the shipped threshold {EVIDENCE_THRESHOLD:g} (and rise >= {MIN_RISE:g}x): "
              f"{flagged_bad}/{len(bad)} degrading flagged, {flagged_null}/{len(null)} healthy flagged; "
              f"degrading ranked first: {ranked_first}; min evidence of degrading {ev1.min():.1f}, "
              f"max of healthy {ev0.max():.1f}")
        if args.plot:
            from companion.plots import require_matplotlib

            plt = require_matplotlib()
            fig, ax = plt.subplots(figsize=(6.4, 3.6))
            ax.semilogy(grid, [max(np.mean(ev0 >= g), 1e-5) for g in grid], "o-", ms=3,
                        label=f"healthy IMUs above (n={ev0.size})")
            ax.semilogy(grid, 10.0 ** -grid, "k--", lw=1, label="nominal 10^-evidence")
            ax.semilogy(grid, [max(np.mean(ev1 >= g), 1e-5) for g in grid], "s-", ms=3, color="firebrick",
                        label=f"N x{args.rise:g} IMUs above (n={ev1.size})")
            ax.axvline(EVIDENCE_THRESHOLD, color="gray", lw=1)
            ax.text(EVIDENCE_THRESHOLD + 0.1, 2e-4, f"threshold {EVIDENCE_THRESHOLD:g}", fontsize=8)
            ax.set_ylim(5e-5, 1.5)
            ax.set_xlabel("evidence threshold (-log10 Bonferroni p)")
            ax.set_ylabel("fraction of IMUs at or above")
            ax.set_title(f"{args.flights} flights of {args.duration:g} s at {args.rate:g} Hz, seed {args.seed}",
                         fontsize=9)
            ax.legend(fontsize=7, loc="lower left")
            ax.grid(alpha=0.3, which="both")
            fig.tight_layout()
            out = os.path.join(ROOT, "docs", "img", "fleet_threshold.png")
            fig.savefig(out, dpi=100)
            print(f"wrote {out}")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def scale(args):
    import resource

    from companion.fleet.synthetic_fleet import simulate_fleet
    from companion.fleet.store import FleetStore

    tmp = tempfile.mkdtemp(prefix="bench_fleet_scale_", dir=args.tmp)
    try:
        vehicles = max(1, args.logs // args.flights)
        flights = args.logs // vehicles
        n = vehicles * flights
        t0 = time.time()
        simulate_fleet(os.path.join(tmp, "logs"), vehicles, flights, args.imus, min(3, vehicles * args.imus), 1.5, "N",
                       args.duration, args.rate, args.seed)
        t_sim = time.time() - t0
        size = sum(os.path.getsize(os.path.join(r, f)) for r, _, fs in os.walk(os.path.join(tmp, "logs")) for f in fs)
        print(f"command: python -m benchmarks.bench_fleet scale --logs {args.logs} --duration {args.duration:g} "
              f"--rate {args.rate:g} --imus {args.imus} --serial-logs {args.serial_logs}")
        print(f"load average at start {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores (a shared machine)")
        print(f"{n} logs ({vehicles} vehicles x {flights} flights), {args.imus} IMU(s) each, {args.duration:g} s at "
              f"{args.rate:g} Hz, {size / 1e6:.0f} MB; simulated in {t_sim:.0f} s")
        # one process, on the first K logs (or all)
        k = min(args.serial_logs or n, n)
        one = os.path.join(tmp, "one")
        os.makedirs(one)
        logs_sorted = sorted(os.path.join(r, f) for r, _, fs in os.walk(os.path.join(tmp, "logs")) for f in fs
                             if f.endswith(".tlog"))
        for p in logs_sorted[:k]:
            os.symlink(p, os.path.join(one, os.path.basename(os.path.dirname(p)) + "_" + os.path.basename(p)))
        s1, _ = _analyze(os.path.join(tmp, "one.sqlite"), one, 0)
        r1 = s1.rate
        print(f"one process: {k} logs in {s1.elapsed_s:.1f} s = {r1:.3f} logs/s"
              + (f" (extrapolated to {n} logs: {n / r1:.0f} s)" if k < n else ""))
        # two Dask workers on all logs
        db = os.path.join(tmp, "fleet.sqlite")
        s2, rss = _analyze(db, os.path.join(tmp, "logs"), 2)
        r2 = s2.rate
        print(f"Dask LocalCluster, 2 worker processes: {n} logs in {s2.elapsed_s:.1f} s = {r2:.3f} logs/s "
              f"({s2.failed} failed; {s2.batch} log(s) per task, the default for {n} logs)")
        print(f"load average now {os.getloadavg()[0]:.1f}")
        print(f"parallel efficiency (rate on 2 workers) / (2 x rate in one process) = {r2 / (2 * r1):.2f} "
              "(wall clock; on a shared machine each run gets the CPU share its process count wins)")
        c1, c2 = s1.cpu_s / max(s1.done + s1.failed, 1), s2.cpu_s / max(s2.done + s2.failed, 1)
        print(f"CPU seconds per log: one process {c1:.3f}, Dask workers {c2:.3f} (+ {s2.main_cpu_s / n:.4f} in the "
              f"client process, which also hosts the scheduler); CPU efficiency {c1 / c2:.2f}")
        if rss:
            m = np.array([x[1] for x in rss if len(x[1]) == 2]) / 1e6
            if len(m) >= 4:
                q = len(m) // 4
                print(f"worker RSS [MB]: first quarter of the run {m[:q].mean(axis=0).round(0).tolist()}, "
                      f"last quarter {m[-q:].mean(axis=0).round(0).tolist()}, max {m.max(axis=0).round(0).tolist()}")
                tenths = [m[int(i * len(m) / 10):max(int((i + 1) * len(m) / 10), int(i * len(m) / 10) + 1)]
                          .mean() for i in range(10)]
                print("worker RSS [MB] by tenth of the run (mean of both workers): "
                      + " ".join(f"{x:.0f}" for x in tenths))
        print(f"this process' peak RSS: {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e3:.0f} MB")
        with FleetStore(db, create=False) as store:
            imus = store.imus()
            veh, imu = imus[len(imus) // 2][0], imus[len(imus) // 2][4]
            store.history(veh, imu)  # warm the page cache once
            times = []
            for _ in range(20):
                t = time.perf_counter()
                rows = store.history(veh, imu)
                times.append(time.perf_counter() - t)
            nrows = store.con.execute("SELECT COUNT(*) FROM results").fetchone()[0]
        print(f"query one IMU's history ({len(rows)} rows of {nrows}): median {1e3 * np.median(times):.2f} ms, "
              f"max {1e3 * max(times):.2f} ms over 20 queries")
        if args.bigdb:
            big_query(args.bigdb)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def big_query(n_logs: int):
    """The history query on a database of ``n_logs`` synthetic logs x 3 IMUs x 3 axes (rows inserted directly)."""
    from companion.fleet.store import FleetStore

    tmp = tempfile.mkdtemp(prefix="bench_fleet_db_")
    try:
        rng = np.random.default_rng(0)
        with FleetStore(os.path.join(tmp, "big.sqlite")) as store:
            def res(i):
                v = i % 50
                return {"path": f"/logs/v{v}/f{i}.tlog", "format": "tlog", "status": "ok", "elapsed_s": 1.0,
                        "log": {"sysid": v + 1, "vehicle": f"veh{v:03d}", "start_time": 1.75e9 + i * 3600.0},
                        "rows": [{"vehicle": f"veh{v:03d}", "sysid": v + 1, "compid": 1, "imu": k,
                                  "message": "RAW_IMU", "axis": a, "status": "ok",
                                  "N": float(rng.uniform(1e-4, 3e-4)), "N_lo": 1e-4, "N_hi": 3e-4}
                                 for k in range(3) for a in ("gx", "gy", "gz")]}

            half = n_logs // 2
            t0 = time.time()
            for i in range(half):
                store.record(f"{i:032x}", res(i), 1000, 0.0)
            t_one = time.time() - t0
            t0 = time.time()
            for b in range(half, n_logs, 20):
                store.record_many([(f"{i:032x}", res(i), 1000, 0.0) for i in range(b, min(b + 20, n_logs))])
            t_many = time.time() - t0
            t_ins = t_one + t_many
            print(f"one writer: {half / t_one:.0f} logs/s with one transaction per log, "
                  f"{(n_logs - half) / t_many:.0f} logs/s with 20 logs per transaction (--batch 20); "
                  f"load average {os.getloadavg()[0]:.1f}")
            store.history("veh025", 1)  # first query: page cache warm-up
            times = []
            for _ in range(20):
                t = time.perf_counter()
                rows = store.history("veh025", 1)
                times.append(time.perf_counter() - t)
        print(f"database of {n_logs} logs ({9 * n_logs} result rows, inserted in {t_ins:.1f} s = "
              f"{n_logs / t_ins:.0f} logs/s by the one writer): one IMU's history ({len(rows)} rows) "
              f"median {1e3 * np.median(times):.2f} ms, max {1e3 * max(times):.2f} ms")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def _noop(i):
    return i


def sched(args):
    """Tasks per second the Dask scheduler of a LocalCluster sustains for no-op tasks."""
    from companion.fleet.dask_runner import close_client, open_client

    client, cluster = open_client(args.workers)
    try:
        client.gather(client.map(_noop, range(100)))  # warm up
        t = time.perf_counter()
        client.gather(client.map(_noop, range(args.tasks), pure=False))
        dt = time.perf_counter() - t
    finally:
        close_client(client, cluster)
    print(f"command: python -m benchmarks.bench_fleet sched --tasks {args.tasks} --workers {args.workers}")
    print(f"{args.tasks} no-op tasks on a LocalCluster of {args.workers} processes: {dt:.1f} s = "
          f"{args.tasks / dt:.0f} tasks/s ({1e3 * dt / args.tasks:.2f} ms per task); load average "
          f"{os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="cmd", required=True)
    c = sub.add_parser("calibrate")
    c.add_argument("--vehicles", type=int, default=50)
    c.add_argument("--flights", type=int, default=10)
    c.add_argument("--imus", type=int, default=3)
    c.add_argument("--duration", type=float, default=60.0)
    c.add_argument("--rate", type=float, default=50.0)
    c.add_argument("--rise", type=float, default=1.5)
    c.add_argument("--seed", type=int, default=1)
    c.add_argument("--workers", type=int, default=2)
    c.add_argument("--plot", action="store_true", help="write docs/img/fleet_threshold.png")
    s = sub.add_parser("scale")
    s.add_argument("--logs", type=int, default=1000)
    s.add_argument("--flights", type=int, default=20, help="flights per vehicle (vehicles = logs / flights)")
    s.add_argument("--duration", type=float, default=600.0)
    s.add_argument("--rate", type=float, default=100.0)
    s.add_argument("--imus", type=int, default=1)
    s.add_argument("--serial-logs", type=int, default=0, help="one-process run on the first K logs only (0: all)")
    s.add_argument("--bigdb", type=int, default=0, help="also time the history query on a database of N logs")
    s.add_argument("--seed", type=int, default=0)
    s.add_argument("--tmp", default=None, help="folder for the temporary logs")
    d = sub.add_parser("sched")
    d.add_argument("--tasks", type=int, default=5000)
    d.add_argument("--workers", type=int, default=2)
    argv = sys.argv[1:]
    if "--quick" in argv:
        s.set_defaults(logs=40, duration=60.0, rate=50.0, flights=10)
    s.add_argument("--quick", action="store_true", help="40 logs of 60 s at 50 Hz, 10 flights per vehicle")
    args = ap.parse_args(argv)
    {"calibrate": calibrate, "scale": scale, "sched": sched}[args.cmd](args)


if __name__ == "__main__":
    sub_cmd = next((a for a in sys.argv[1:] if a in ("calibrate", "scale", "sched")), "")
    sys.exit(results.run(main, f"bench_fleet {sub_cmd}".strip()))
