from cosim.process import main
from subsims.flexbody.subsim import FlexBody

raise SystemExit(main(FlexBody))
