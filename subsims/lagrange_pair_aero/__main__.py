from cosim.process import main
from subsims.lagrange_pair_aero.subsim import LagrangePairAero

raise SystemExit(main(LagrangePairAero))
