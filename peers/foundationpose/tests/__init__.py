"""Tests of hitl_foundationpose against a stand-in FoundationPose (tests/stand_in/estimater.py).

Run from peers/foundationpose: `python -m unittest discover -s tests -t .` (hitl's
perception/tests/foundationpose_peer.rs runs them under `cargo test` with the test venv).
"""
