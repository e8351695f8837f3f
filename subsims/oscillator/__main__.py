from cosim.process import main
from subsims.oscillator.subsim import Mass

raise SystemExit(main(Mass))
