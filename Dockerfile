# vgn-service: the grasp-planning HTTP API on port 8000 (CPU build).
FROM python:3.11-slim

# What open3d links against (libusb above all), and libgomp, the OpenMP runtime of open3d and torch.
RUN apt-get update \
    && apt-get install -y --no-install-recommends libusb-1.0-0 libgl1 libegl1 libx11-6 libudev1 libidn2-0 libgomp1 \
    && rm -rf /var/lib/apt/lists/*

WORKDIR /app
COPY pyproject.toml README.md ./
COPY vgn_contract vgn_contract
COPY client client
COPY service service
COPY sim_worker sim_worker
# vgn-train, vgn-pack-data and vgn-data are installed with the package; training/ is what they run.
COPY training training
COPY vgn_data vgn_data
# torch==2.13.0 is pinned in pyproject.toml; the CPU index keeps the CUDA stack out of the image.
RUN pip install --no-cache-dir --extra-index-url https://download.pytorch.org/whl/cpu ".[service]"

ENV VGN_DEVICE=cpu
# The gRPC front end (vgn.v1.GraspPlanning) listens beside HTTP on all interfaces of the container.
ENV VGN_GRPC_HOST=0.0.0.0 VGN_GRPC_PORT=50051
EXPOSE 8000 50051
HEALTHCHECK --interval=30s --timeout=5s CMD python -c "import httpx; httpx.get('http://127.0.0.1:8000/healthz').raise_for_status()"
CMD ["uvicorn", "service.app:app", "--host", "0.0.0.0", "--port", "8000"]
