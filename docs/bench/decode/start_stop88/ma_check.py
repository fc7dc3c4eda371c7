import sys
from formats.lfcfile import open_lfc
from rlfc import RlfcDecoder
import rlfc.render  # noqa: F401
path = sys.argv[1]
RlfcDecoder(open_lfc(path)).decode_block(0, 0, 0, 0)
print("ma before", 'numpy.ma' in sys.modules, end=" ")
d3 = RlfcDecoder(open_lfc(path))
rad = min(d3.rows, d3.cols) / 3
d3.renderer(cache_mib=1024).render((d3.rows - 1) / 2, (d3.cols - 1) / 2 + rad)
print("after", 'numpy.ma' in sys.modules)
