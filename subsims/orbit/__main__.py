from cosim.process import main
from subsims.orbit.subsim import Orbit

raise SystemExit(main(Orbit))
