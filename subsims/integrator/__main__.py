from cosim.process import main
from subsims.integrator.subsim import Integrator

raise SystemExit(main(Integrator))
