# usage: python THIS.py SCENE OUT.lfc KEY_LANE_SYMBOLS  (an encode at 40 dB with rlfc.txencode.KEY_LANE_SYMBOLS set)
import sys
sys.path.insert(0, ".")
import rlfc.txencode as T
T.KEY_LANE_SYMBOLS = int(sys.argv[3])
from formats.cli import main
sys.exit(main(["encode", sys.argv[1], sys.argv[2], "--target-psnr", "40", "--json"]))
