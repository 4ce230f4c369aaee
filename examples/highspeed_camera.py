"""The 1,666 fps high-speed camera (seed 002): readout timing, region of interest, and the link plan.

Run: ``python examples/highspeed_camera.py``.
"""

from viform.isp import link_plan
from viform.sensors.highspeed_timing import lux13hs_timing

timing = lux13hs_timing("reduced")  # 4 pixels per clock per row, top and bottom readout
for roi in (None, "1280x720", "640x360"):
    window = timing.window(roi)
    print(f"{window.width}×{window.height}: {timing.frame_rate_hz(roi):,.1f} frames/s")
plan = link_plan(timing.frame_rate_hz("1280x720"), 720, 1280, interface="cameralink", sustain_s=3600.0)
print(f"CameraLink carries {plan['link_max_frame_rate_hz']:.1f} frames/s of 1280×720: keep 1 frame in "
      f"{plan['decimation']} ({plan['transmitted_frame_rate_hz']:.1f} frames/s); the DDR ring holds "
      f"{plan['buffer_capacity_frames']} frames ({plan['buffer_record_s']:.2f} s of full-rate recording)")
