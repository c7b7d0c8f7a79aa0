"""Read a specmux recording with the field's usual OME library (tifffile) and check it.

Usage: python tools/ome/check_recording.py DIR [FRAMES]

Checks that frames.ome.tif opens as an OME series of FRAMES uint16 planes whose per-plane
DeltaT follow the frame period, that calibration.ome.tif holds dark, flat and one float32 plane
per pattern, and that frames.jsonl has one record per frame with matching frame ids.
Exits non-zero with a one-line message on the first mismatch.
"""
import json
import sys
import xml.etree.ElementTree as ET

import tifffile

OME = "{http://www.openmicroscopy.org/Schemas/OME/2016-06}"


def fail(msg):
    print(f"check_recording: {msg}", file=sys.stderr)
    sys.exit(1)


def main():
    if len(sys.argv) < 2:
        fail("usage: check_recording.py DIR [FRAMES]")
    d = sys.argv[1]
    with tifffile.TiffFile(f"{d}/frames.ome.tif") as tif:
        if not tif.is_ome:
            fail("frames.ome.tif is not read as OME-TIFF")
        frames = tif.series[0].asarray()
        meta = ET.fromstring(tif.ome_metadata)
    if frames.dtype != "uint16" or frames.ndim != 3:
        fail(f"frames: dtype {frames.dtype}, shape {frames.shape}; expected uint16 (T, Y, X)")
    n = frames.shape[0]
    if len(sys.argv) > 2 and n != int(sys.argv[2]):
        fail(f"{n} frames, expected {sys.argv[2]}")
    planes = meta.findall(f".//{OME}Plane")
    times = [float(p.get("DeltaT")) for p in planes]
    if len(times) != n or any(b <= a for a, b in zip(times, times[1:])):
        fail(f"{len(times)} plane times for {n} frames, or not increasing: {times[:5]}")
    with tifffile.TiffFile(f"{d}/calibration.ome.tif") as tif:
        cal = tif.series[0].asarray()
    if cal.dtype != "float32" or cal.shape[0] < 3 or cal.shape[1:] != frames.shape[1:]:
        fail(f"calibration: dtype {cal.dtype}, shape {cal.shape}")
    if not (cal[1].mean() > cal[0].mean()):
        fail("calibration: the flat is not brighter than the dark frame")
    records = [json.loads(line) for line in open(f"{d}/frames.jsonl")]
    if len(records) != n:
        fail(f"{len(records)} frame records for {n} frames")
    print(f"ok: {n} frames {frames.shape[1]}x{frames.shape[2]} uint16, "
          f"mean {frames.mean():.1f} DN; calibration {cal.shape[0]} planes; "
          f"frame ids {records[0]['frame_id']}..{records[-1]['frame_id']}")


main()
