from cosim.process import main
from subsims.attitude.subsim import Attitude

raise SystemExit(main(Attitude))
