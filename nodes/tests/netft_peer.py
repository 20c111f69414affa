"""A Net F/T client no one here wrote (pynetft, PyPI) against the simulated box: it reads the box's
settings page over HTTP and its RDT stream, and prints, as one JSON line, the calibration it found, how
many samples it got, their mean force in the box's unit and how far its conversion of the counts is from
counts / counts-per-unit. Arguments: host, RDT port, HTTP port."""

import json
import sys

import pynetft


def main() -> None:
    host, rdt_port, http_port = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
    config = pynetft.Config(sensor_host=host, rdt_port=rdt_port, http_port=http_port, receive_timeout=0.5)
    with pynetft.Client(config) as client:
        if not client.wait_for_first_sample(5.0):
            raise SystemExit(f"no sample within 5 s: {client.health()}")
        samples = []
        for sample in client.samples(timeout=2.0):
            samples.append(sample)
            if len(samples) >= 300:
                break
        health = client.health()
    configuration = health.sensor_configuration
    if configuration is None:
        raise SystemExit(f"pynetft read no configuration: {health}")
    calibration = configuration.calibration
    mean_force = [sum(s.force[i] for s in samples) / len(samples) for i in range(3)]
    conversion_error = max(
        abs(s.force[i] - s.raw_wrench[i] / calibration.counts_per_force_unit) for s in samples for i in range(3)
    )
    print(
        json.dumps(
            {
                "product": configuration.product_name,
                "source": configuration.source.value,
                "counts_per_force": calibration.counts_per_force_unit,
                "counts_per_torque": calibration.counts_per_torque_unit,
                "force_unit": calibration.force_unit.value,
                "torque_unit": calibration.torque_unit.value,
                "samples": len(samples),
                "mean_force": mean_force,
                "conversion_error": conversion_error,
            }
        )
    )


if __name__ == "__main__":
    main()
