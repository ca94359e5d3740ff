"""Robot descriptions shipped as data (installed as ``qpcoord.robots.descriptions``)."""
