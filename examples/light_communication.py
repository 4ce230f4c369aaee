"""Light communication (seed 000 §7): an LED 100 m away sends a text message by on-off keying at
10 kbit/s; the spike camera's pixels receive it from their spike timing.

Run: ``python examples/light_communication.py``.
"""

from viform.display.lightcomm import LEDTransmitter, LightLink, bits_to_bytes, bytes_to_bits, simulate_link

link = LightLink(transmitter=LEDTransmitter(luminous_intensity_cd=1.0), distance_m=100.0, ambient_lux=1.0)
message = "spike cameras see light as it changes"
result = simulate_link(link, bytes_to_bits(message.encode()), bitrate_bps=10e3, modulation="ook", seed=4)
print(f"sent:     {message}")
print(f"received: {bits_to_bytes(result.bits_received).decode(errors='replace')}")
print(f"{result.bit_errors} bit errors in {result.n_bits} bits")
