"""Reports: the demo, response plots and other figures."""
