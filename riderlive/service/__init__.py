"""The live service: the web process (FastAPI on uvicorn) around the tick process."""
