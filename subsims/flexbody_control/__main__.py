from cosim.process import main
from subsims.flexbody_control.subsim import AttitudeControl

raise SystemExit(main(AttitudeControl))
