"""Opens a UBO2003 zip with the btf-extractor package's own reader (Ubo2003), independently
of btfmrf, and prints what it sees as JSON. Run through ubo2003_reader.sh, which prepares the
environment."""
import importlib.util
import json
import sys

spec = importlib.util.spec_from_file_location("ubo2003", sys.argv[1])
ubo2003 = importlib.util.module_from_spec(spec)
spec.loader.exec_module(ubo2003)

btf = ubo2003.Ubo2003(sys.argv[2])
angles = sorted(btf.angles_set)
first = btf.angles_to_image(*angles[0])
last = btf.angles_to_image(*angles[-1])
print(json.dumps({
    "images": len(angles),
    "views": len({(a[2], a[3]) for a in angles}),
    "lights": len({(a[0], a[1]) for a in angles}),
    "shape": list(first.shape),
    "dtype": str(first.dtype),
    "first": list(angles[0]),
    "last": list(angles[-1]),
    "mean_first": float(first.mean()),
    "mean_last": float(last.mean()),
}))
