from cosim.process import main
from subsims.double_integrator.subsim import DoubleIntegrator

raise SystemExit(main(DoubleIntegrator))
