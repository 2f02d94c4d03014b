"""The OpenEnv server (`app.py`) in OpenEnv's environment layout (`server/app.py`, `server/Dockerfile`)."""
