"""Sensor models, one module per architecture, behind :class:`viform.sensors.base.Sensor`."""
