"""HealthcareGym as an OpenEnv environment (openenv 0.10): `environment.py` (the `Environment` over the
env's one episode core, with the task API), `models.py` (the wire types), `client.py` (a typed
WebSocket client), `server/app.py` (the app and its limits, `hcgym serve --openenv`), and
`openenv.yaml` / `server/Dockerfile` in OpenEnv's environment layout.

Needs the `openenv` extra, which cannot share a venv with the `mcp` extra (openenv's fastmcp needs
mcp < 2): `make openenv` builds `.venv-openenv`. Nothing is imported here, so the package itself
imports without openenv.
"""
