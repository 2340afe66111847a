#!/usr/bin/env python3
"""Writes a RealSense .bag of synthetic depth with librealsense's own recorder
(pyrealsense2's software device), as a D435 recording would be: a Z16 depth stream,
its intrinsics, the sensor's depth units, LZ4 chunks.

usage: realsense_bag.py OUT.bag [--frames N] [--fps F]

The scene (the same as depth_ingest's PNG test): a box face 2.5 m ahead of the camera
filling columns 240-399 and rows 140-339 of a 640x480 image (fx = fy = 380, principal
point at the centre); no return (0) everywhere else. Needs pyrealsense2 older than 2.58:
from 2.58 on, its recorder writes ROS 2 .db3 files only (`make test` installs 2.57).
"""
import argparse
import sys
import time

import numpy as np
import pyrealsense2 as rs

WIDTH, HEIGHT, F = 640, 480, 380.0
DEPTH_UNITS = 0.001


def depth_image():
    d = np.zeros((HEIGHT, WIDTH), dtype=np.uint16)
    d[140:340, 240:400] = int(round(2.5 / DEPTH_UNITS))
    return d


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out")
    ap.add_argument("--frames", type=int, default=10)
    ap.add_argument("--fps", type=int, default=15)
    a = ap.parse_args()
    if not a.out.endswith(".bag"):
        sys.exit("error: the output must be a .bag file")

    dev = rs.software_device()
    dev.register_info(rs.camera_info.name, "Synthetic D435")
    dev.register_info(rs.camera_info.serial_number, "000000000001")
    sensor = dev.add_sensor("Stereo Module")
    intr = rs.intrinsics()
    intr.width, intr.height = WIDTH, HEIGHT
    intr.fx = intr.fy = F
    intr.ppx, intr.ppy = WIDTH / 2.0, HEIGHT / 2.0
    intr.model = rs.distortion.brown_conrady
    intr.coeffs = [0.0] * 5
    vs = rs.video_stream()
    vs.type, vs.index, vs.uid = rs.stream.depth, 0, 0
    vs.width, vs.height, vs.fps = WIDTH, HEIGHT, a.fps
    vs.bpp, vs.fmt, vs.intrinsics = 2, rs.format.z16, intr
    profile = sensor.add_video_stream(vs, True).as_video_stream_profile()
    sensor.add_read_only_option(rs.option.depth_units, DEPTH_UNITS)

    # LZ4-compressed chunks, as the RealSense Viewer records.
    rec = rs.recorder(a.out, dev, True)
    rec_sensor = rec.query_sensors()[0]
    rec_sensor.open(profile)
    rec_sensor.start(lambda f: None)
    pixels = depth_image()
    t0_ms = time.time() * 1000.0
    for i in range(a.frames):
        fr = rs.software_video_frame()
        fr.pixels = pixels
        fr.stride, fr.bpp = WIDTH * 2, 2
        fr.timestamp = t0_ms + i * 1000.0 / a.fps
        fr.domain = rs.timestamp_domain.hardware_clock
        fr.frame_number = i + 1
        fr.depth_units = DEPTH_UNITS
        fr.profile = profile
        sensor.on_video_frame(fr)
        time.sleep(1.0 / a.fps)
    time.sleep(0.2)
    rec_sensor.stop()
    rec_sensor.close()
    # The recorder writes the index and closes the file when it is destroyed.
    del rec_sensor, rec
    print(f"wrote {a.out}: {a.frames} depth frames {WIDTH}x{HEIGHT} at {a.fps} fps")


if __name__ == "__main__":
    main()
