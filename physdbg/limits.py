"""The range of every number physdbg reads: scenes, overrides, mesh files and poses.

Every number is 0 or at most MAX_MAGNITUDE in size, and every length, mass and time that
something is divided by is at least MIN_SCALE: then products of a few of them (v·dt,
a·dt², |x|², m·v²) stay finite, and no derived quantity (a unit normal, an inverse mass,
a step count) can overflow or vanish. SI units: use reduced units for atoms or planets.
A mesh's corners are coordinates like any other (at most MAX_MAGNITUDE m from the
origin), and a triangle smaller than MIN_AREA has no normal worth the name.
"""

MAX_MAGNITUDE = 1e12
MIN_SCALE = 1e-12
MAX_INTEGER = 10**12
MIN_AREA = MIN_SCALE * MIN_SCALE  # m²: a triangle with less area is degenerate
