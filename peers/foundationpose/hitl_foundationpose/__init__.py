"""hitl_foundationpose: NVIDIA FoundationPose as an external pose estimator of hitl.

`python -m hitl_foundationpose SOCKET --foundationpose-dir DIR` serves it over hitl's protocol
`hitl-pose` version 1 (hitl's docs/perception.md); README.md says how to run it on the lab's GPU
machine. Modules: `wire` (the protocol's bytes), `session` (register/track and the paper's depth
normalisation around FoundationPose), `peer` (the socket, the command line).
"""
