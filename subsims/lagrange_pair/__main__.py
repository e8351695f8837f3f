from cosim.process import main
from subsims.lagrange_pair.subsim import LagrangePair

raise SystemExit(main(LagrangePair))
