"""Light: radiometry (lux → photons → electrons) and scenes (light per pixel over time)."""
