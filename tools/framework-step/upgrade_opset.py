"""burn-import needs ONNX opset >= 16; the shared YOLOX (opset 11) and MobileFaceNet (13)
files are converted with onnx's own version converter: `pip install onnx`, then
`python upgrade_opset.py ../../../shared/models OUT_DIR`."""
import sys

import onnx
from onnx import version_converter

src, out = sys.argv[1], sys.argv[2]
for name in ["yolox_nano", "mobilefacenet_casia"]:
    model = onnx.load(f"{src}/{name}.onnx")
    onnx.save(version_converter.convert_version(model, 16), f"{out}/{name}.onnx")
