from cosim.process import main
from subsims.aero.subsim import Aero

raise SystemExit(main(Aero))
