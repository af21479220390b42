"""UM-Bridge models served by the reference Python package (`pip install umbridge`), for the
interoperability tests of iuq's client.

Usage: python3 umbridge_model_server.py PORT

Serves on 127.0.0.1 only (the package's `serve_models` binds every interface; its call to
aiohttp's `run_app` is given host="127.0.0.1" here):
- "forward": inputs [2, 1] (two vectors), outputs [2, 1];
  out0 = [a + b, a * b], out1 = [sin(c)] for input [[a, b], [c]]; raises ValueError for a < 0
  (the package then answers HTTP 500 without an error object); gradient supported.
- "with-std": input [1], outputs [1, 1]: the value 2x and its std 0.1 (a surrogate's answer).
"""

import functools
import math
import sys

import umbridge
import umbridge.um


class Forward(umbridge.Model):
    def __init__(self):
        super().__init__("forward")

    def get_input_sizes(self, config):
        return [2, 1]

    def get_output_sizes(self, config):
        return [2, 1]

    def __call__(self, parameters, config):
        (a, b), (c,) = parameters
        if a < 0:
            raise ValueError("negative a")
        scale = config.get("scale", 1.0) if isinstance(config, dict) else 1.0
        return [[scale * (a + b), scale * a * b], [scale * math.sin(c)]]

    def supports_evaluate(self):
        return True

    def gradient(self, out_wrt, in_wrt, parameters, sens, config):
        (a, b), (c,) = parameters
        if out_wrt == 0 and in_wrt == 0:
            # d(a+b)/d(a,b) = [1, 1]; d(ab)/d(a,b) = [b, a]
            return [sens[0] + sens[1] * b, sens[0] + sens[1] * a]
        if out_wrt == 1 and in_wrt == 1:
            return [sens[0] * math.cos(c)]
        return [0.0] * (2 if in_wrt == 0 else 1)

    def supports_gradient(self):
        return True


class WithStd(umbridge.Model):
    def __init__(self):
        super().__init__("with-std")

    def get_input_sizes(self, config):
        return [1]

    def get_output_sizes(self, config):
        return [1, 1]

    def __call__(self, parameters, config):
        return [[2.0 * parameters[0][0]], [0.1]]

    def supports_evaluate(self):
        return True


if __name__ == "__main__":
    port = int(sys.argv[1])
    umbridge.um.web.run_app = functools.partial(umbridge.um.web.run_app, host="127.0.0.1", print=None)
    umbridge.serve_models([Forward(), WithStd()], port=port, max_workers=4)
