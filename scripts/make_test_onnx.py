#!/usr/bin/env python3
"""Write small ONNX models that follow (or deliberately break) hitl's perception contract.

Used by perception/tests/onnx.rs; see docs/perception.md for the contract. Needs the `onnx`
package (run `make setup` for the project's venv).

  make_test_onnx.py pose      OUT --hw H W --values 16 floats  (row-major 4x4 target-in-camera)
  make_test_onnx.py posequat  OUT --hw H W --values 7 floats   (qw qx qy qz tx ty tz)
  make_test_onnx.py keypoints OUT --hw H W --values 2K floats  (u0 v0 u1 v1 ... pixels)
  make_test_onnx.py mask      OUT --hw H W                     (mask = depth > 0)
  make_test_onnx.py bad-output OUT --hw H W                    (output named "banana")
  make_test_onnx.py bad-input  OUT --hw H W                    (rgb with 4 channels)
"""
import argparse
import sys

try:
    import onnx
    from onnx import TensorProto, helper
except ImportError:
    sys.exit("make_test_onnx.py: the onnx package is missing: run make setup")


def tensor_in(name, c, h, w):
    return helper.make_tensor_value_info(name, TensorProto.FLOAT, [1, c, h, w])


def const(name, dims, values):
    return helper.make_node(
        "Constant", [], [name],
        value=helper.make_tensor(name + "_v", TensorProto.FLOAT, dims, values))


def constant_output_model(out_name, dims, values, h, w, rgb_channels=3):
    """out = C + 0 * sum(depth): a constant that still reads its inputs."""
    nodes = [
        const("c", dims, values),
        const("zero", [], [0.0]),
        helper.make_node("ReduceSum", ["depth"], ["s"], keepdims=0),
        helper.make_node("Mul", ["s", "zero"], ["s0"]),
        helper.make_node("Add", ["c", "s0"], [out_name]),
    ]
    inputs = [tensor_in("rgb", rgb_channels, h, w), tensor_in("depth", 1, h, w)]
    outputs = [helper.make_tensor_value_info(out_name, TensorProto.FLOAT, dims)]
    return helper.make_graph(nodes, "hitl_test", inputs, outputs)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("kind")
    ap.add_argument("out")
    ap.add_argument("--hw", nargs=2, type=int, required=True)
    ap.add_argument("--values", nargs="*", type=float, default=[])
    a = ap.parse_args()
    h, w = a.hw
    v = a.values
    if a.kind == "pose":
        assert len(v) == 16, "pose needs 16 values"
        g = constant_output_model("pose", [1, 4, 4], v, h, w)
    elif a.kind == "posequat":
        assert len(v) == 7, "posequat needs 7 values"
        g = constant_output_model("pose", [1, 7], v, h, w)
    elif a.kind == "keypoints":
        assert len(v) % 2 == 0 and v, "keypoints need u v pairs"
        g = constant_output_model("keypoints", [1, len(v) // 2, 2], v, h, w)
    elif a.kind == "mask":
        nodes = [
            const("zero", [], [0.0]),
            helper.make_node("Greater", ["depth", "zero"], ["b"]),
            helper.make_node("Cast", ["b"], ["mask"], to=TensorProto.FLOAT),
        ]
        g = helper.make_graph(
            nodes, "hitl_test", [tensor_in("depth", 1, h, w)],
            [helper.make_tensor_value_info("mask", TensorProto.FLOAT, [1, 1, h, w])])
    elif a.kind == "bad-output":
        g = constant_output_model("banana", [1, 4, 4], [0.0] * 16, h, w)
    elif a.kind == "bad-input":
        g = constant_output_model("pose", [1, 4, 4], [0.0] * 16, h, w, rgb_channels=4)
    else:
        sys.exit(f"unknown kind {a.kind!r}")
    model = helper.make_model(g, opset_imports=[helper.make_opsetid("", 17)])
    model.ir_version = 8
    onnx.checker.check_model(model)
    onnx.save(model, a.out)


if __name__ == "__main__":
    main()
