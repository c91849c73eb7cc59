#!/usr/bin/env python3
"""The viewer's page in a real browser (headless Chromium), checked against the library.

For one case it writes (or takes) a page, opens it in headless Chromium and
  1. reads back, through the page (#probe=...), the world position of every frame at two knot
     times of each trajectory and compares them with `trellis kinematics` to 1e-9;
  2. checks that the page reported no JavaScript error and finished setting up;
  3. takes a screenshot and checks that it is not blank: pixels differ from the background, and
     bodies (the page's blue) are drawn;
  4. where the page draws constraint force arrows (a solid trajectory of a model with constraints),
     reads them back through the page (their start and their direction times their length over the
     scale) and compares them with the forces computed here from the library's λ
     (trellis_mech.compute_dynamics at the knot, --python-path) and `trellis kinematics`: to 1e-9
     relative to the largest force, positions to 1e-9 m;
  5. reports the file size and, with --timing, the load time (navigation start to the first
     picture complete) over several loads (median, spread, machine load) and the time per frame of
     playback (#bench=10). Nothing is judged on time: the figures are printed.

Cases: pendulum (examples/scenes/pendulum.json with a swing), urdf_arm (tests/data/viewer/arm.urdf
with an STL mesh and a box, cylinder and sphere), hand (examples/scenes/hand.json: a 3 s motion and
20 ghosted variants, the size of the main job's page), page (a given page and the files it shows).

Exit status: 0 pass, 1 fail, 77 skip (no browser installed: the message says so).
"""
import argparse
import csv
import html
import io
import json
import math
import os
import re
import shutil
import struct
import subprocess
import sys
import tempfile
import zlib

SKIP = 77
TOLERANCE = 1e-9  # metres: the page holds float64 poses; only a rigid offset is composed in it


def ghost_tolerance(rounding, radius):
    """The limit for a ghost whose stored numbers the page says were changed by at most `rounding`
    (float32 differences from the first trajectory, ~6e-8 of the deviation: ~1e-11 m for closed
    loops beside their reference; or float32 coordinates, ~6e-8 of the pose). A frame's position is
    p + R(q) r: p is off by ≤ ε per axis, and a quaternion off by ≤ ε per entry (‖δq‖ ≤ 2ε) turns r
    by ≤ 2‖δq‖ ‖r‖ = 4ε ‖r‖, with ‖r‖ ≤ 2 · radius (two frame origins inside the page's bounding
    box). So ε (1 + 8 radius), doubled for margin, and never below TOLERANCE."""
    return max(TOLERANCE, 2 * rounding * (1 + 8 * radius))


def fail(message):
    print("FAIL: " + message)
    sys.exit(1)


def find_browser():
    for name in (os.environ.get("TRELLIS_CHROMIUM"), "chromium", "chromium-browser", "google-chrome"):
        if name and shutil.which(name):
            return shutil.which(name)
    return None


def chromium(browser, work, url, extra, timeout=240):
    """Runs headless Chromium as the tests must (root, no sandbox, no network, a fresh profile)."""
    profile = tempfile.mkdtemp(prefix="profile_", dir=work)
    command = [browser, "--headless", "--no-sandbox", "--disable-gpu", "--enable-unsafe-swiftshader",
               "--disable-quic", "--no-first-run", "--disable-background-networking",
               "--disable-component-update", "--disable-sync", "--user-data-dir=" + profile] + extra + [url]
    try:
        done = subprocess.run(command, capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        fail("chromium did not finish within %d s: %s" % (timeout, " ".join(command)))
    finally:
        shutil.rmtree(profile, ignore_errors=True)
    if done.returncode != 0:
        fail("chromium exited with status %d: %s\n%s" % (done.returncode, " ".join(command), done.stderr[-2000:]))
    return done.stdout


def run(command):
    done = subprocess.run(command, capture_output=True, text=True)
    if done.returncode != 0:
        fail("%s exited with status %d:\n%s%s" % (" ".join(command), done.returncode, done.stdout, done.stderr))
    return done.stdout


def element_text(dom, element_id):
    match = re.search(r'<pre id="%s"[^>]*>(.*?)</pre>' % re.escape(element_id), dom, re.S)
    if not match:
        fail("the page has no element #%s after loading" % element_id)
    return html.unescape(match.group(1))


def read_png(path):
    """RGB(A) rows of an 8-bit, non-interlaced PNG (what Chromium writes)."""
    data = open(path, "rb").read()
    if data[:8] != b"\x89PNG\r\n\x1a\n":
        fail(path + " is not a PNG file")
    pos, idat = 8, b""
    while pos < len(data):
        length = struct.unpack(">I", data[pos:pos + 4])[0]
        kind, body = data[pos + 4:pos + 8], data[pos + 8:pos + 8 + length]
        pos += 12 + length
        if kind == b"IHDR":
            width, height, depth, colour, _, _, interlace = struct.unpack(">IIBBBBB", body)
        elif kind == b"IDAT":
            idat += body
        elif kind == b"IEND":
            break
    if depth != 8 or interlace != 0 or colour not in (2, 6):
        fail("%s: unexpected PNG format (depth %d, colour type %d, interlace %d)" % (path, depth, colour, interlace))
    bpp = 3 if colour == 2 else 4
    raw, stride = zlib.decompress(idat), width * bpp
    rows, previous, i = [], bytearray(stride), 0
    for _ in range(height):
        kind, line = raw[i], bytearray(raw[i + 1:i + 1 + stride])
        i += 1 + stride
        for x in range(stride):
            a = line[x - bpp] if x >= bpp else 0
            b = previous[x]
            c = previous[x - bpp] if x >= bpp else 0
            if kind == 1:
                line[x] = (line[x] + a) & 255
            elif kind == 2:
                line[x] = (line[x] + b) & 255
            elif kind == 3:
                line[x] = (line[x] + ((a + b) >> 1)) & 255
            elif kind == 4:
                p = a + b - c
                pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
                line[x] = (line[x] + (a if pa <= pb and pa <= pc else b if pb <= pc else c)) & 255
        rows.append(line)
        previous = line
    return width, height, bpp, rows


def check_screenshot(path):
    width, height, bpp, rows = read_png(path)
    background = (0xf4, 0xf5, 0xf7)
    differing = blue = 0
    for line in rows:
        for x in range(0, width * bpp, bpp):
            r, g, b = line[x], line[x + 1], line[x + 2]
            if abs(r - background[0]) + abs(g - background[1]) + abs(b - background[2]) > 30:
                differing += 1
                if b > r + 40 and b > g + 10:
                    blue += 1
    share = differing / float(width * height)
    print("screenshot %s: %dx%d, %.1f%% of the pixels differ from the background, %d body-blue pixels"
          % (path, width, height, 100 * share, blue))
    if share < 0.005:
        fail("the screenshot is blank: only %.3f%% of its pixels differ from the background" % (100 * share))
    if blue < 50:
        fail("the screenshot shows no body (only %d pixels of the bodies' blue)" % blue)


def kinematics_rows(trellis, scene, trajectory):
    text = run([trellis, "kinematics", scene, "--trajectory", trajectory])
    reader = csv.reader(io.StringIO(text))
    header = next(reader)
    return header, [[float(v) for v in row] for row in reader]


def knot_times(path):
    with open(path) as f:
        rows = [r for r in csv.reader(f) if r and not r[0].startswith("#")]
    return [float(r[0]) for r in rows[1:]]


# ---- cases that write their page -------------------------------------------------------------

def hand_trajectories(trellis, source, work, count):
    """A 3 s motion of the hand (31 knots) and count - 1 variants (amplitudes up to 2 % larger, like
    closed loops beside their reference): what the main job's page holds."""
    info = json.loads(run([trellis, "info", "--json", os.path.join(source, "examples/scenes/hand.json")]))
    configs = [c["name"] if isinstance(c, dict) else c for c in info["configs"]]
    inputs = [u["name"] if isinstance(u, dict) else u for u in info["inputs"]]
    paths = []
    for k in range(count):
        path = os.path.join(work, "hand_motion_%d.csv" % k)
        with open(path, "w") as f:
            f.write(",".join(["t"] + configs + ["d" + c for c in configs] + inputs) + "\n")
            for i in range(31):
                t = 0.1 * i
                w = 2 * math.pi / 3.0
                q = [0.25 * math.sin(w * t + 0.3 * j) * (1 + 0.001 * k) for j in range(len(configs))]
                dq = [0.25 * w * math.cos(w * t + 0.3 * j) * (1 + 0.001 * k) for j in range(len(configs))]
                f.write(",".join(repr(v) for v in [t] + q + dq + [0.0] * len(inputs)) + "\n")
        paths.append(path)
    return paths


def make_page(args, work):
    trellis, source = args.trellis, args.source
    page = os.path.join(work, "view.html")
    if args.case == "pendulum":
        scene = os.path.join(source, "examples/scenes/pendulum.json")
        trajectories = [os.path.join(source, "examples/trajectories/pendulum_swing.csv")]
    elif args.case == "urdf_arm":
        scene = os.path.join(source, "tests/data/viewer/arm.urdf")
        trajectories = [os.path.join(source, "tests/data/viewer/arm_motion.csv"),
                        os.path.join(source, "tests/data/viewer/arm_motion_slow.csv")]
    elif args.case == "hand":
        scene = os.path.join(source, "examples/scenes/hand.json")
        trajectories = hand_trajectories(trellis, source, work, 21)
    else:
        raise ValueError(args.case)
    command = [trellis, "view", scene, "--out", page]
    for t in trajectories:
        command += ["--trajectory", t]
    print(run(command).strip())
    return page, scene, trajectories


def rotation(kin, header, frame):
    """The frame's world rotation matrix from `trellis kinematics`' unit quaternion (qw, qx, qy, qz)."""
    import numpy
    w, x, y, z = (kin[header.index(frame + "." + k)] for k in ("qw", "qx", "qy", "qz"))
    return numpy.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def check_arrows(args, scene, trajectories, chosen, probe, result):
    """The page's force arrows against λ from the library (see the module's docstring, item 4)."""
    solid = [i for i, t in enumerate(result["trajectories"][:len(trajectories)]) if t["arrows"]]
    if not solid:
        print("force arrows: none on this page")
        return
    if not args.python_path:
        # The Python bindings are optional (TRELLIS_BUILD_PYTHON); test_view.cpp checks the arrows' data.
        print("force arrows: NOT CHECKED in the browser (no --python-path: trellis_mech is not built)")
        return
    sys.path.insert(0, args.python_path)
    try:
        import numpy
        import trellis_mech
    except ImportError as e:
        fail("cannot import trellis_mech from %s to check the force arrows: %s" % (args.python_path, e))
    loaded = trellis_mech.load_scene(scene)
    model = loaded.model
    data = trellis_mech.Data(model)
    spec = json.load(open(scene))["constraints"]
    names = [row["name"] for row in json.loads(run([args.trellis, "info", "--json", scene]))["constraints"]]
    compared, worst_force, worst_point, largest = 0, 0.0, 0.0, 0.0
    for index in solid:
        path = trajectories[index]
        with open(path) as f:
            rows = [r for r in csv.reader(f) if r and not r[0].startswith("#")]
        header, knots = rows[0], [[float(v) for v in r] for r in rows[1:]]
        n, m = model.nq, model.nu
        kin_header, kin_rows = kinematics_rows(args.trellis, scene, path)
        for t in chosen[index]:
            knot = next(r for r in knots if r[0] == t)
            lam = numpy.zeros(model.nc)
            status = trellis_mech.compute_dynamics(model, data, numpy.array(knot[1:1 + n]), numpy.array(knot[1 + n:1 + 2 * n]),
                                                   numpy.array(knot[1 + 2 * n:1 + 2 * n + m]), lambda_=lam)
            if not status.ok:
                fail("%s, t = %r: the dynamics fail: %s" % (path, t, status))
            kin = next(r for r in kin_rows if r[0] == t)
            position = lambda frame: numpy.array(kin[kin_header.index(frame + ".x"):kin_header.index(frame + ".x") + 3])
            for arrow in result["trajectories"][index]["arrows"]:
                got = arrow["values"][probe.index(t)]
                if got is None:
                    fail("%s, t = %r: the page hides the arrow of %s" % (path, t, arrow["names"]))
                expected_force, expected_point = numpy.zeros(3), None
                for name in arrow["names"]:
                    r = names.index(name)
                    c = spec[r]
                    # The force on the constraint's first body, at its first point (the kinds the
                    # pages tested use; constraint_forces.hpp lists every kind).
                    if c["type"] == "point":
                        expected_force[{"x": 0, "y": 1, "z": 2}[c["axis"]]] += lam[r]
                    elif c["type"] == "distance":
                        expected_force += lam[r] * 2 * (position(c["frame1"]) - position(c["frame2"]))
                    elif c["type"] == "point_on_plane":
                        # λ n on the plane's body, n = R_plane n_plane, at the point body's point.
                        expected_force += lam[r] * rotation(kin, kin_header, c["plane_frame"]).dot(numpy.array(c["normal"]))
                    else:
                        fail("check_arrows: constraint kind %s not handled by this test" % c["type"])
                    expected_point = position(c["point_frame"] if c["type"] == "point_on_plane" else c["frame1"])
                largest = max(largest, numpy.linalg.norm(expected_force))
                worst_force = max(worst_force, numpy.abs(numpy.array(got[3:]) - expected_force).max())
                worst_point = max(worst_point, numpy.abs(numpy.array(got[:3]) - expected_point).max())
                compared += 1
    if not worst_force <= TOLERANCE * largest or not worst_point <= TOLERANCE:
        fail("force arrows: worst difference %.3g N (limit %.3g: 1e-9 of the largest force %.3g N), points %.3g m (limit %g)"
             % (worst_force, TOLERANCE * largest, largest, worst_point, TOLERANCE))
    print("force arrows: %d readings (arrows of %d trajectories at 2 knots each) match the library's constraint forces; "
          "worst difference %.3g N (largest force %.3g N), points %.3g m" % (compared, len(solid), worst_force, largest, worst_point))


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trellis", required=True)
    parser.add_argument("--source", required=True)
    parser.add_argument("--case", required=True, choices=["pendulum", "urdf_arm", "hand", "page"])
    parser.add_argument("--work", required=True)
    parser.add_argument("--page")
    parser.add_argument("--scene")
    parser.add_argument("--trajectories", help="comma-separated: the page's first trajectories, in order")
    parser.add_argument("--screenshot-copy", help="also save the screenshot (with the controls) here")
    parser.add_argument("--timing", action="store_true",
                        help="measure the load time (goal 2 s, reported, not judged) and the time per frame of playback")
    parser.add_argument("--runs", type=int, default=3, help="loads timed with --timing (the median is reported)")
    parser.add_argument("--python-path", help="directory holding trellis_mech (the force arrows' expected values)")
    args = parser.parse_args()

    browser = find_browser()
    if not browser:
        print("SKIP: no browser: install Debian's chromium (scripts/setup.sh installs it) or set TRELLIS_CHROMIUM")
        return SKIP
    os.makedirs(args.work, exist_ok=True)
    if args.case == "page":
        if not (args.page and args.scene and args.trajectories):
            fail("--case page needs --page, --scene and --trajectories")
        page, scene, trajectories = args.page, args.scene, args.trajectories.split(",")
        if not os.path.isfile(page):
            fail("no page " + page + " (the test that writes it failed?)")
    else:
        page, scene, trajectories = make_page(args, args.work)
    url = "file://" + os.path.abspath(page)
    size = os.path.getsize(page)

    # 1. Positions through the page at two knots of each trajectory, against `trellis kinematics`.
    chosen = []
    for t in trajectories:
        knots = knot_times(t)
        chosen.append([knots[min(1, len(knots) - 1)], knots[len(knots) // 2]])
    probe = sorted(set(v for c in chosen for v in c))
    dom = chromium(browser, args.work, url + "#probe=" + ",".join(repr(v) for v in probe), ["--dump-dom"])
    status = json.loads(element_text(dom, "trellis-status"))
    if status.get("errors"):
        fail("the page reported JavaScript errors: %s" % status["errors"])
    if not status.get("ready"):
        fail("the page did not finish setting up: %s" % status)
    result = json.loads(element_text(dom, "trellis-probe"))
    if len(result["trajectories"]) < len(trajectories):
        fail("the page shows %d trajectories, expected at least %d" % (len(result["trajectories"]), len(trajectories)))
    compared, worst, worst_exact, widest = 0, 0.0, 0.0, TOLERANCE
    for index, path in enumerate(trajectories):
        header, rows = kinematics_rows(args.trellis, scene, path)
        shown = result["trajectories"][index]["frames"]
        tolerance = ghost_tolerance(result["trajectories"][index]["rounding"], result["radius"])
        widest = max(widest, tolerance)
        for t in chosen[index]:
            row = next((r for r in rows if r[0] == t), None)
            if row is None:
                fail("%s: no kinematics row at t = %r" % (path, t))
            at = probe.index(t)
            for column, name in enumerate(header):
                if not name.endswith(".x"):
                    continue
                frame = name[:-2]
                if frame not in shown:
                    fail("the page has no frame '%s'" % frame)
                got = shown[frame][at]
                for axis in range(3):
                    error = abs(got[axis] - row[column + axis])
                    worst = max(worst, error)
                    compared += 1
                    if tolerance == TOLERANCE:
                        worst_exact = max(worst_exact, error)
                    if not error <= tolerance:
                        fail("%s, t = %r, frame '%s', axis %d: page %r, trellis kinematics %r (difference %.3g > %g)"
                             % (os.path.basename(path), t, frame, axis, got[axis], row[column + axis], error, tolerance))
    if compared == 0:
        fail("nothing compared")
    print("positions: %d coordinates of %d trajectories at 2 knots each match trellis kinematics; worst difference "
          "%.3g m (%.3g m among those held to %g; the widest limit, from a ghost's reported rounding: %.3g)"
          % (compared, len(trajectories), worst, worst_exact, TOLERANCE, widest))
    check_arrows(args, scene, trajectories, chosen, probe, result)

    # 2. Load time and playback cost (no probe work in the measured load).
    if not args.timing:
        print("page %s: %.2f MB (load time not measured: --timing)" % (os.path.basename(page), size / 1e6))
    # The load time: navigation start to the first picture complete, as the page measures it, over
    # several loads; reported with the machine's load, never judged (it measures the machine too).
    loads, status = [], None
    for attempt in range(args.runs if args.timing else 0):
        before = os.getloadavg()[0]
        dom = chromium(browser, args.work, url + "#bench=10", ["--dump-dom"])
        measured = json.loads(element_text(dom, "trellis-status"))
        if measured.get("errors") or not measured.get("ready"):
            fail("the page reported errors when loaded for timing: %s" % measured)
        loads.append((measured["loadMs"], before))
        if status is None or measured["loadMs"] < status["loadMs"]:
            status = measured
    if loads:
        times = sorted(l[0] for l in loads)
        median = times[len(times) // 2] if len(times) % 2 else 0.5 * (times[len(times) // 2 - 1] + times[len(times) // 2])
        print("page %s: %.2f MB, %d trajectories, %d pose samples; load (navigation start to the first picture) median "
              "%.0f ms of %d loads (%.0f to %.0f ms; goal 2000 ms), machine load %.1f to %.1f per core; of the fastest: "
              "three.js and the page's markup %.0f ms, the page's script %.0f ms (data %.0f ms); playback %.1f ms per "
              "frame, %d draw calls (headless, software WebGL)"
              % (os.path.basename(page), size / 1e6, status["trajectories"], status["samples"], median, len(times),
                 times[0], times[-1], min(l[1] for l in loads) / (os.cpu_count() or 1),
                 max(l[1] for l in loads) / (os.cpu_count() or 1), status["marks"]["scriptStartMs"], status["scriptMs"],
                 status["marks"]["parseMs"] + status["marks"]["decodeMs"], status["benchMsPerFrame"], status["drawCalls"]))

    # 3. A screenshot that is not blank.
    middle = 0.5 * (min(c[0] for c in chosen) + max(c[1] for c in chosen))
    shot = os.path.join(args.work, "screenshot.png")
    if os.path.exists(shot):
        os.remove(shot)
    chromium(browser, args.work, url + "#bare&t=%r" % middle, ["--window-size=960,600", "--screenshot=" + shot])
    if not os.path.isfile(shot):
        fail("chromium wrote no screenshot")
    check_screenshot(shot)
    if args.screenshot_copy:
        chromium(browser, args.work, url + "#t=%r" % middle, ["--window-size=1280,800", "--screenshot=" + args.screenshot_copy])
        print("screenshot with the controls: " + args.screenshot_copy)
    print("PASS")
    return 0


if __name__ == "__main__":
    sys.exit(main())
