"""Prediction models (pure numpy/scipy, SI units, no files).

- :mod:`.gearset`       Gearset geometry and Speeds
- :mod:`.assembly`      can it be built: coaxiality, planet tip clearance (module-free)
- :mod:`.mesh_phasing`  ideal and shaft-hole-error phasing (spec sections 1, 2)
- :mod:`.tolerance`     Monte Carlo tolerance statistics (spec section 2)
- :mod:`.bearing`       planet bearing moments, single and double pinion (spec section 4)
- :mod:`.tilt`          coupled bearing tilt / load distribution solve (spec section 5)
- :mod:`.load_sharing`  planet load sharing from ring strain (spec section 6)
- :mod:`._geometry`     angle reduction, ShaftHoleErrors, argument checks shared by
                        mesh_phasing and tolerance
"""

from .gearset import Gearset, Speeds, rad_s_to_rpm, rpm_to_rad_s

__all__ = ["Gearset", "Speeds", "rpm_to_rad_s", "rad_s_to_rpm"]
