"""The reference Python client (`pip install umbridge`) against an iuq UM-Bridge server.

Usage: python3 umbridge_client_check.py URL MODEL [BAD_POINT]

Prints one JSON object: the model list, sizes, support, an evaluation at [1.5, -0.5] (and with
the computational std if the model reports one), the gradient when supported, and the error
messages the client raises for a wrong input size, an unknown model and (with BAD_POINT, a
comma-separated point) a failing evaluation.
"""

import json
import sys

import umbridge

url, name = sys.argv[1], sys.argv[2]
bad_point = [float(v) for v in sys.argv[3].split(",")] if len(sys.argv) > 3 else None

result = {"models": umbridge.supported_models(url)}
model = umbridge.HTTPModel(url, name)
result["input_sizes"] = model.get_input_sizes()
result["output_sizes"] = model.get_output_sizes()
result["output_sizes_with_std"] = model.get_output_sizes({"computational_std": True})
result["support"] = {
    "evaluate": model.supports_evaluate(),
    "gradient": model.supports_gradient(),
    "apply_jacobian": model.supports_apply_jacobian(),
    "apply_hessian": model.supports_apply_hessian(),
}
d = result["input_sizes"][0]
point = [1.5, -0.5, 0.25, 2.0, 1.0, 0.5][:d]
result["evaluate"] = model([point])
try:
    result["evaluate_with_std"] = model([point], {"computational_std": True})
except Exception as e:  # noqa: BLE001 - the message is what the test checks
    result["evaluate_with_std_error"] = str(e)
if model.supports_gradient():
    m = result["output_sizes"][0]
    result["gradient"] = model.gradient(0, 0, [point], [1.0] * m)
    result["apply_jacobian"] = model.apply_jacobian(0, 0, [point], [1.0] + [0.0] * (d - 1))

errors = {}
try:
    model([point + [0.0]])
except Exception as e:  # noqa: BLE001
    errors["wrong_size"] = str(e)
try:
    umbridge.HTTPModel(url, "no-such-model")
except Exception as e:  # noqa: BLE001
    errors["unknown_model"] = str(e)
if bad_point is not None:
    try:
        model([bad_point])
    except Exception as e:  # noqa: BLE001
        errors["failing_point"] = str(e)
try:
    model.apply_hessian(0, 0, 0, [point], [1.0], [1.0] * d)
except Exception as e:  # noqa: BLE001
    errors["hessian"] = str(e)
result["errors"] = errors
print(json.dumps(result))
