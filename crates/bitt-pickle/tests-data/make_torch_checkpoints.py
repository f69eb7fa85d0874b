"""Writes the torch checkpoint fixtures of crates/bitt-pickle/src/torch.rs (run from this folder).

torch_zip.pth: torch.save (zip format); torch_legacy.pth: the same object with
_use_new_zipfile_serialization=False (the legacy format of the `lpips` package's weights and
torchvision's VGG16). Contents: an nn.Linear(3, 2) state dict (with its _metadata) plus
tensors of several dtypes, a transposed view, a view at a storage offset sharing its storage
with another entry, a 0-d tensor and an nn.Parameter.
"""

import torch

torch.manual_seed(0)
lin = torch.nn.Linear(3, 2)
with torch.no_grad():
    lin.weight.copy_(torch.tensor([[0.5, -1.0, 2.0], [0.25, 3.0, -0.125]]))
    lin.bias.copy_(torch.tensor([1.5, -2.5]))
sd = lin.state_dict()
full = torch.arange(6, dtype=torch.float32) * 1.5
sd["full"] = full
sd["tail"] = full[2:]  # storage offset 2, shares full's storage
sd["transposed"] = torch.arange(6, dtype=torch.float32).reshape(2, 3).t()
sd["half"] = torch.tensor([1.0, -2.0, 0.333251953125, 65504.0], dtype=torch.float16)
sd["bf16"] = torch.tensor([1.0, -0.5], dtype=torch.bfloat16)
sd["double"] = torch.tensor([0.1, 1e300], dtype=torch.float64)
sd["long"] = torch.tensor([-3, 0, 1 << 40], dtype=torch.int64)
sd["int"] = torch.tensor([7, -8], dtype=torch.int32)
sd["byte"] = torch.tensor([0, 255], dtype=torch.uint8)
sd["bool"] = torch.tensor([True, False])
sd["scalar"] = torch.tensor(4.0)
sd["param"] = torch.nn.Parameter(torch.tensor([9.0, 10.0]))
torch.save(sd, "torch_zip.pth")
torch.save(sd, "torch_legacy.pth", _use_new_zipfile_serialization=False)
for k, v in sd.items():
    print(k, tuple(v.shape), v.dtype, v.flatten().tolist())
