#!/usr/bin/env python3
# Wavelength sweep of a Lambertian plate, standard library only.
import json, os, urllib.request

URL = os.environ.get("RAYSWEEP_URL", "http://127.0.0.1:8350")

def call(path, body=None):  # POST when there is a body; raises HTTPError on 4xx/5xx
    data = body if body is None or isinstance(body, bytes) else json.dumps(body).encode()
    req = urllib.request.Request(URL + path, data, {"Content-Type": "application/json"})
    with urllib.request.urlopen(req) as r:
        return json.load(r)

with open("plate.json", "rb") as f:
    scene = call("/v1/scenes", f.read())["id"]
job = call(f"/v1/scenes/{scene}/jobs", {
    "params": {"plate.bsdf.reflectance.value": {"wavelengths": [400, 700], "values": [0.2, 0.8]}},
    "contexts": [{"id": f"w{w}", "wavelength": w} for w in range(400, 701, 50)]})
with urllib.request.urlopen(URL + job["href_events"]) as events:  # server-sent events
    end = [line for line in events if line.startswith(b'data: {"state"')][-1]  # event: end
assert json.loads(end[6:])["state"] == "succeeded", end
for r in call(job["href_results"])["results"]:
    print(r["wavelength"], call(r["href"])["data"][0])
