#!/usr/bin/env python3
"""Markdown tables for bench/stream_bench.sh: reads one run folder and prints the report.

Usage: bench/stream_report.py RUN_DIR

Inputs (all written by stream_bench.sh): machine.txt, runs.jsonl (command lines and the load
average before each), limits.json, and <section>/<flight>/{summary.json,frames.csv}.
Python 3 standard library only.
"""
import csv
import json
import math
import os
import statistics
import sys

# Backes et al., Table 1: seconds to load a whole clip region (1024-px tiles, 16-bit colour),
# from a SATA SSD (500 MB/s) and a hard disk (156 MB/s).
PAPER_S = {"1280x720": (0.20191, 0.30543), "1920x1080": (0.20768, 0.31337),
           "3840x2160": (0.64730, 0.65707)}
PAPER_NAMES = {"1280x720": "HD", "1920x1080": "FHD", "3840x2160": "UHD"}
SEED_SPEED_PX_S = 1000      # seed 000: about 1 km/s, roughly 1000 level-0 px/s
TARGET_SPEED_PX_S = 50000   # issue 3 target
MAX_CENTRE_STEP_TILES = 4   # ResidencyOptions::max_centre_step_tiles default
PAN_FPS = 60


def load_json(path):
    with open(path) as f:
        return json.load(f)


def mib(n):
    return n / (1 << 20)


def fmt_ms(v):
    return "-" if v is None else ("%.0f" % v if v >= 100 else "%.1f" % v)


def median_or_none(values):
    values = [v for v in values if v is not None]
    return statistics.median(values) if values else None


def read_frames(path):
    with open(path) as f:
        return list(csv.DictReader(f))


def per_jump_work(summary, frames):
    """Bytes read and tiles loaded between each jump and the next (frames.csv is cumulative)."""
    starts = [j["at_s"] * 1000 for j in summary["jumps"]] + [math.inf]
    work, previous_bytes, previous_tiles = [], 0, 0
    for a, b in zip(starts, starts[1:]):
        window = [r for r in frames if a <= float(r["t_ms"]) < b]
        if not window:
            work.append((0, 0))
            continue
        last_bytes, last_tiles = int(window[-1]["bytes_read"]), int(window[-1]["tiles_loaded"])
        work.append((last_bytes - previous_bytes, last_tiles - previous_tiles))
        previous_bytes, previous_tiles = last_bytes, last_tiles
    return work


def main():
    args = sys.argv[1:]
    if not args:
        print(__doc__, file=sys.stderr)
        return 2
    run = args[0]
    runs = []
    if os.path.exists(os.path.join(run, "runs.jsonl")):
        with open(os.path.join(run, "runs.jsonl")) as f:
            runs = [json.loads(line) for line in f if line.strip()]
    by_out = {r["out"]: r for r in runs}

    def load_note(section):
        """Quiet means other processes kept under 0.2 cores busy, on average, during the
        flights (the load average before a flight also counts this script's previous one)."""
        flights = [r for r in runs if r["section"] == section and "foreign_cores" in r]
        if not flights:
            return ""
        mean = statistics.mean(r["foreign_cores"] for r in flights)
        worst = max(r["foreign_cores"] for r in flights)
        text = ("other processes kept %.2f cores busy on average during these flights (at most "
                "%.2f in one flight; /proc/stat minus the flight's own CPU time)" % (mean, worst))
        if mean > 0.2:
            return "\n**Not a quiet machine**: %s; the figures are slower than the machine.\n" % text
        return "\nQuiet machine: %s.\n" % text

    out = []
    w = out.append
    machine = os.path.join(run, "machine.txt")
    if os.path.exists(machine):
        w("### Machine\n\n```\n" + open(machine).read().rstrip() + "\n```\n")

    # Limits: this run's, or failing that (--only without limits) the latest earlier run's.
    limits_path = os.path.join(run, "limits.json")
    if not os.path.exists(limits_path):
        parent = os.path.dirname(os.path.abspath(run))
        earlier = sorted(d for d in os.listdir(parent)
                         if d.startswith("run-") and os.path.exists(
                             os.path.join(parent, d, "limits.json")))
        if earlier:
            limits_path = os.path.join(parent, earlier[-1], "limits.json")
    limits = load_json(limits_path) if os.path.exists(limits_path) else None
    if limits:
        cores = limits["cores"]
        r1 = limits["jpeg256_decode_tiles_s_one_core"]
        cc = limits["cold_check"]
        w("### Physical limits\n")
        if os.path.dirname(os.path.abspath(limits_path)) != os.path.abspath(run):
            w("(from `%s`)\n" % os.path.dirname(limits_path))
        w("| limit | measured | how |")
        w("|---|---|---|")
        w("| disk, sequential | %.0f MB/s | `dd if=FILE of=/dev/null bs=4M iflag=direct`, "
          "1 GiB of random bytes, median of 3 (%s MB/s) |"
          % (limits["disk_seq_direct_bps"] / 1e6,
             ", ".join("%.0f" % (v / 1e6) for v in limits["disk_seq_direct_runs_bps"])))
        w("| disk, buffered after drop | %.0f MB/s | same file after `dd iflag=nocache "
          "count=0` (fincore: %d bytes resident), `bs=4M` with kernel read-ahead |"
          % (limits["buffered_cold_bps"] / 1e6, limits["test_file_resident_after_drop"]))
        w("| disk, 64 KiB random reads, QD 1 | %.0f MB/s | O_DIRECT `preadv` at 2000 random "
          "aligned offsets |" % (limits["random_64k_qd1_direct_bps"] / 1e6))
        w("| page cache | %.1f GB/s | `dd bs=1M` of the same file after `cat` (fincore: %d of "
          "%d bytes resident), median of 3, one thread |"
          % (limits["page_cache_bps"] / 1e9, limits["test_file_resident_after_cat"],
             limits["test_file_bytes"]))
        w("| JPEG 256x256 RGB q85 4:2:0 decode, one core | %.0f tiles/s | `tessera_codec_bench`"
          " `%s` |" % (r1, limits["codec_bench_name"]))
        w("| JPEG 256 decode, all %d cores | %.0f tiles/s | one core x %d |"
          % (cores, r1 * cores, cores))
        w("")
        w("`fly --cold` check: after `cat`, %.1f MiB of the %.1f MiB archive were resident "
          "(fincore); after a 50 ms `fly --cold` flight that read %.1f MiB, %.1f MiB were. "
          "posix_fadvise(DONTNEED) does drop the archive's pages in this guest; whether a "
          "hypervisor below caches the disk image cannot be seen from here, which is what "
          "the direct-I/O bandwidth above measures."
          % (mib(cc["resident_before"]), mib(cc["archive_bytes"]), mib(cc["fly_bytes_read"]),
             mib(cc["resident_after"])))
        w("")

    def ideal_ms(bytes_read, tiles, tile_px, bandwidth_bps):
        """Time the bytes need at the bandwidth plus decoding every tile on all cores."""
        if not limits:
            return None
        decode_s = tiles * (tile_px / 256) ** 2 / (limits["jpeg256_decode_tiles_s_one_core"]
                                                  * limits["cores"])
        return 1000 * (bytes_read / bandwidth_bps + decode_s)

    # Table 1.
    table1 = os.path.join(run, "table1")
    if os.path.isdir(table1):
        w("### Time to load a clip region after a jump (Backes et al., Table 1)\n")
        w("| viewport | tile px | clip n | page cache | full detail ms | clip region ms "
          "(max) | read per jump | tiles per jump | bound A: codec-bench rate, ms | "
          "measured / A | bound B: same tiles, all cores, ms | measured / B | update p99 ms | "
          "read ampl. | paper SSD / HD s |")
        w("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
        names = sorted(os.listdir(table1), key=lambda n: (
            int(n.split("-")[0][1:]), int(n.split("-")[1].split("x")[0]), n.endswith("cold")))
        for name in names:
            d = os.path.join(table1, name)
            if not os.path.exists(os.path.join(d, "summary.json")):
                continue
            tile_px = int(name.split("-")[0][1:])
            viewport = name.split("-")[1]
            state = name.split("-")[2]
            s = load_json(os.path.join(d, "summary.json"))
            work = per_jump_work(s, read_frames(os.path.join(d, "frames.csv")))
            jumps = s["jumps"][1:]   # the first entry is the start, which also opens the archive
            work = work[1:]
            full = [j["full_detail_ms"] for j in jumps]
            clip = [j["clip_region_ms"] for j in jumps]
            vw, vh = map(int, viewport.split("x"))
            n = 2 * math.ceil(max(vw, vh) / tile_px)
            bandwidth = None
            if limits:
                bandwidth = limits["page_cache_bps"] if state == "warm" else \
                    limits["disk_seq_direct_bps"]
            ideals = [ideal_ms(b, t, tile_px, bandwidth) for b, t in work] if limits else []
            m_clip, m_ideal = median_or_none(clip), median_or_none(ideals)
            # Bound B: the bytes at the bandwidth plus the jump's own tiles decoded on every
            # core (fly --decode-bound), instead of the codec benchmark's one tile.
            bounds_b = [1000 * b / bandwidth + j["decode_bound_ms"]
                        for (b, _), j in zip(work, jumps)
                        if bandwidth and j.get("decode_bound_ms") is not None]
            m_bound_b = median_or_none(bounds_b)
            missing = sum(v is None for v in clip)
            clip_text = "%s (%s)" % (fmt_ms(m_clip), fmt_ms(max(v for v in clip if v is not None))
                                     if m_clip is not None else "-")
            if missing:
                clip_text += ", %d of %d never idle" % (missing, len(clip))
            paper = PAPER_S.get(viewport)
            w("| %s %s | %d | %d | %s | %s | %s | %.1f MiB | %.0f | %s | %s | %s | %s | %.3f | "
              "%.2f | %s |" % (
                PAPER_NAMES.get(viewport, ""), viewport, tile_px, n, state,
                fmt_ms(median_or_none(full)), clip_text,
                mib(statistics.median(b for b, _ in work)) if work else 0,
                statistics.median(t for _, t in work) if work else 0,
                fmt_ms(m_ideal),
                "%.2f" % (m_clip / m_ideal) if m_clip and m_ideal else "-",
                fmt_ms(m_bound_b),
                "%.2f" % (m_clip / m_bound_b) if m_clip and m_bound_b else "-",
                s["update_ms"]["p99"], s["read_amplification"],
                "%.2f / %.2f" % paper if paper else "-"))
        w("")
        w("Medians over the four jumps of the keyframe path jumps.path (five spots on land) (the start, which also opens the archive "
          "and loads the coarsest level, is left out; it is in each summary.json). \"full "
          "detail\": until every visible tile at the desired level was resident; \"clip "
          "region\": until the loader was idle, the whole clip region and the levels under it "
          "loaded (Table 1's measure). \"Read/tiles per jump\": what the loader read and "
          "decoded between that jump and the next (frames.csv). \"Bytes at bandwidth + "
          "decode\": those bytes at the page-cache (warm) or direct-I/O disk (cold) bandwidth "
          "above, plus decoding, one after the other: the physical bound if nothing "
          "overlapped; overlap can beat it. Bound A counts the decode at the codec "
          "benchmark's one-core rate for one tile decoded over and over into the same buffer "
          "(hot caches) times the cores, a 1024-px tile as 16 256-px tiles. Bound B measures "
          "it: after the flight, `fly --decode-bound` decodes the tiles each jump uploaded "
          "again, from memory, on as many threads as the loader has, into buffers faulted in "
          "beforehand, with nothing else running (its median per jump is in summary.json). "
          "Clip region times are the loader's own time stamp of running out of work, not the "
          "next frame's. The paper's figures are 1024-px tiles of 16-bit colour, "
          "uncompressed, on a 6-core Ryzen 5 1600.")
        w(load_note("table1"))

    # Eviction.
    ev = os.path.join(run, "eviction")
    if os.path.isdir(ev):
        w("### Eviction: LRU vs viewer-shift (FHD, 256-px JPEG, warm page cache)\n")
        w("| path | cache MiB | policy | misses | evictions | tiles loaded | read MiB | "
          "re-read MiB | frames below full detail | hit rate | update p99 ms |")
        w("|---|---|---|---|---|---|---|---|---|---|---|")
        for path in ("back-and-forth", "spiral"):
            base_file = os.path.join(ev, path + "-nolimit", "summary.json")
            base = load_json(base_file) if os.path.exists(base_file) else None
            for budget in ("nolimit", "64", "128"):
                for policy in (("viewer-shift",) if budget == "nolimit" else
                               ("lru", "viewer-shift")):
                    name = "%s-%s" % (path, budget) + ("" if budget == "nolimit" else "-" + policy)
                    f = os.path.join(ev, name, "summary.json")
                    if not os.path.exists(f):
                        continue
                    s = load_json(f)
                    c = s["cache"]
                    below = s["frames"] - round(s["frames"] * s["frames_full_detail_pct"] / 100)
                    w("| %s | %s | %s | %d | %d | %d | %.1f | %s | %d (%.1f%%) | %.3f | %.3f |" % (
                        path, "4096 (baseline)" if budget == "nolimit" else budget, s["eviction"],
                        c["misses"], c["evictions"], s["tiles_loaded"], mib(s["bytes_read"]),
                        "%.1f" % mib(s["bytes_read"] - base["bytes_read"]) if base and
                        budget != "nolimit" else "-",
                        below, 100 - s["frames_full_detail_pct"], c["hit_rate"],
                        s["update_ms"]["p99"]))
        w("")
        w("Same path, speed (4096 px/s), %d fps and budget for both policies. \"back-and-forth\":"
          " a keyframe file panning over a quarter of the image width and back (back-and-forth"
          ".path in the run folder); \"spiral\": the built-in spiral. \"re-read\": bytes read "
          "beyond the 4096-MiB baseline flight of the same path, which never evicts. The "
          "clip region of FHD with 256-px tiles (16 x 16 tiles, 192 KiB decoded each, plus "
          "the levels under it) alone takes about 64 MiB." % PAN_FPS)
        w(load_note("eviction"))

    # Pan speed.
    sp = os.path.join(run, "speed")
    if os.path.isdir(sp):
        w("### Highest pan speed at full detail (FHD, 256-px JPEG, warm page cache, %d fps)\n"
          % PAN_FPS)
        w("Each flight follows a lawn-mower path over the image (raster-SPEED.path in the run's "
          "speed folder): rows 16 tiles (one FHD clip region) apart, along x and down at SPEED, "
          "so the view keeps entering tiles it has not seen; a flight lasts 6 s or until the "
          "whole image was swept. Upload budget: the default, 16 MiB a frame (85 RGB tiles of "
          "256 px) and at most 128 tiles.\n")
        w("| speed px/s | frames at full detail, after the first | all frames | fully covered |"
          " tiles loaded | decode ms per tile | update p99 ms | update max ms | read ampl. |")
        w("|---|---|---|---|---|---|---|---|---|")
        flights = []
        for name in os.listdir(sp):
            f = os.path.join(sp, name, "summary.json")
            if name.startswith("pan-") and os.path.exists(f):
                flights.append((int(name[4:]), os.path.join(sp, name)))
        decode_ms_per_tile = []
        for speed, d in sorted(flights):
            s = load_json(os.path.join(d, "summary.json"))
            rows = read_frames(os.path.join(d, "frames.csv"))
            first = next((i for i, r in enumerate(rows) if float(r["coverage_desired"]) >= 1),
                         len(rows))
            rest = rows[first:]
            steady = 100.0 * sum(float(r["coverage_desired"]) >= 1 for r in rest) / len(rest) \
                if rest else 0
            per_tile = s["decode_ms_total"] / s["tiles_loaded"] if s["tiles_loaded"] else 0
            decode_ms_per_tile.append(per_tile)
            w("| %d | %.2f%% %s | %.2f%% | %.2f%% | %d | %.3f | %.3f | %.3f | %.2f |" % (
                speed, steady, "pass" if steady >= 99 else "**fail**",
                s["frames_full_detail_pct"], s["frames_fully_covered_pct"], s["tiles_loaded"],
                per_tile, s["update_ms"]["p99"], s["update_ms"]["max"], s["read_amplification"]))
        w("")
        search_file = os.path.join(sp, "search.json")
        if os.path.exists(search_file):
            search = load_json(search_file)
            w("**Highest speed with >= 99%% of frames at full detail: %d px/s** (lowest failing "
              "speed tried: %s px/s); seed 000 flew about %d px/s; issue 3's target is %d px/s."
              % (search["highest_pass_px_s"], search["lowest_fail_px_s"] or "none",
                 SEED_SPEED_PX_S, TARGET_SPEED_PX_S))
            w("")
        if limits:
            t, vw, vh = 256, 1920, 1080
            n = 2 * math.ceil(max(vw, vh) / t)
            rows_visible = math.ceil(vh / t) + 1
            r_all = limits["jpeg256_decode_tiles_s_one_core"] * limits["cores"]
            v_clip = r_all * t / (n * 4 / 3)
            v_visible = r_all * t / (rows_visible * 4 / 3)
            v_step = MAX_CENTRE_STEP_TILES * t * PAN_FPS
            w("Where decoding on all cores saturates. Panning along x at v level-0 px/s, "
              "columns of level-0 tiles enter at v / t per second; the residency loads the "
              "whole column of the clip region, n = 2 ceil(max(w, h) / t) tiles (eq. 3), and "
              "at level l a column of n / 2^l tiles every 2^l t / v seconds, so the levels "
              "together need 4/3 as many:")
            w("")
            w("    tiles/s needed = (v / t) * n * 4/3        =>   v_sat = R * t / (n * 4/3)")
            w("")
            text = ("with R the decode rate of all cores. FHD, t = 256: n = %d, R = %d x %.0f = "
                    "%.0f tiles/s, so **v_sat = %.0f px/s** for the clip region. Decoding only "
                    "the visible rows (ceil(h / t) + 1 = %d instead of n) would saturate at %.0f "
                    "px/s. The residency also moves the clip centre by at most %d tiles per "
                    "frame (max_centre_step_tiles), a kinematic cap of %d x %d x %d = %d px/s at "
                    "%d fps."
                    % (n, limits["cores"], limits["jpeg256_decode_tiles_s_one_core"], r_all,
                       v_clip, rows_visible, v_visible, MAX_CENTRE_STEP_TILES,
                       MAX_CENTRE_STEP_TILES, t, PAN_FPS, v_step, PAN_FPS))
            per = statistics.median(decode_ms_per_tile) if decode_ms_per_tile else 0
            if per > 0:
                r_flight = limits["cores"] * 1000 / per
                text += (" Inside the flights, decoding took %.3f ms of wall time per tile "
                         "(median over the flights of decode_ms_total / tiles_loaded, which "
                         "includes time the loader threads spent preempted), i.e. R = %.0f "
                         "tiles/s on %d cores and v_sat = %.0f px/s."
                         % (per, r_flight, limits["cores"], r_flight * t / (n * 4 / 3)))
            w(text)
            w("")
        w(load_note("speed"))

    commands = [r for r in runs]
    if commands:
        w("### Command lines\n")
        w("Every command of this run, with the 1-minute load average before it and the "
          "cores other processes kept busy while it ran, is in `runs.jsonl`; for example:\n")
        w("```")
        seen = set()
        for r in commands:
            key = (r["section"], r["name"].split("-")[0])
            if key in seen:
                continue
            seen.add(key)
            w("%s   # load %.2f, others %.2f cores" % (r["command"], r["load1"],
                                                      r.get("foreign_cores", 0)))
        w("```")
    print("\n".join(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
