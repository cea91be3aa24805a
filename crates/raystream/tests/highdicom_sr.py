"""highdicom (an independent implementation) on DICOM Imaging Measurement Reports (TID 1500):
- `highdicom_sr.py read REPORT.dcm` prints what highdicom finds in a report, as JSON: each
  measurement group by its template (1501: measurements of images, 1411: of a segment), with
  its tracking identifier, finding, finding sites, referenced segment and measurements
  (concept code, value, unit, derivation and method codes);
- `highdicom_sr.py write SERIES_DIR OUT.dcm` writes a report on the series' first image: a
  planar ROI group (TID 1410: a plaque in the aorta, a polyline region, its area, a coded
  severity) and a group of image measurements (TID 1501: a blood vessel's largest diameter)."""
import glob, json, sys

import highdicom as hd
import numpy as np
import pydicom
from pydicom.sr.codedict import codes


def code(c):
    """A coded concept's value (a content item's, through its value)."""
    while c is not None and not isinstance(c, str):
        c = c.value
    return c


def measurements(group):
    return [{"concept": m.name.value, "value": m.value, "unit": m.unit.value,
             "derivation": code(m.derivation), "method": code(m.method)}
            for m in group.get_measurements()]


def read(path):
    sr = hd.sr.srread(path)
    report = sr.content
    groups = []
    for g in report.get_image_measurement_groups():
        groups.append({"template": "1501", "tracking_id": g.tracking_identifier,
                       "finding": code(g.finding_type),
                       "sites": [code(s) for s in g.finding_sites],
                       "measurements": measurements(g)})
    for g in report.get_volumetric_roi_measurement_groups():
        seg = g.referenced_segment
        groups.append({"template": "1411", "tracking_id": g.tracking_identifier,
                       "finding": code(g.finding_type),
                       "segmentation": seg.referenced_sop_instance_uid if seg else None,
                       "segment": seg.referenced_segment_numbers if seg else None,
                       "source_series": seg.source_series_for_segmentation.value if seg else None,
                       "measurements": measurements(g)})
    devices = [o.observer_identifying_attributes.name for o in report.get_observer_contexts()]
    print(json.dumps({"sop_class": sr.SOPClassUID, "study": sr.StudyInstanceUID,
                      "devices": devices, "groups": groups}))


def write(series, out):
    src = pydicom.dcmread(sorted(glob.glob(series + "/*.dcm"))[0])
    device = hd.sr.ObserverContext(
        observer_type=codes.cid270.Device,
        observer_identifying_attributes=hd.sr.DeviceObserverIdentifyingAttributes(
            uid=hd.UID(), name="highdicom test"))
    region = hd.sr.ImageRegion(
        graphic_type=hd.sr.GraphicTypeValues.POLYLINE,
        graphic_data=np.array([[10.0, 10.0], [20.0, 10.0], [20.0, 20.0], [10.0, 10.0]]),
        source_image=hd.sr.SourceImageForRegion(src.SOPClassUID, src.SOPInstanceUID))
    planar = hd.sr.PlanarROIMeasurementsAndQualitativeEvaluations(
        tracking_identifier=hd.sr.TrackingIdentifier(uid=hd.UID(), identifier="plaque 1"),
        referenced_region=region, finding_type=codes.SCT.Plaque,
        finding_sites=[hd.sr.FindingSite(codes.SCT.Aorta)],
        measurements=[hd.sr.Measurement(name=codes.SCT.Area, value=42.5,
                                        unit=codes.UCUM.SquareMillimeter)],
        qualitative_evaluations=[hd.sr.QualitativeEvaluation(
            hd.sr.CodedConcept("246112005", "SCT", "Severity"),
            hd.sr.CodedConcept("6736007", "SCT", "Moderate"))])
    image = hd.sr.MeasurementsAndQualitativeEvaluations(
        tracking_identifier=hd.sr.TrackingIdentifier(uid=hd.UID(), identifier="vessel"),
        finding_type=codes.SCT.BloodVessel,
        measurements=[hd.sr.Measurement(name=codes.SCT.Diameter, value=7.25,
                                        unit=codes.UCUM.Millimeter, derivation=codes.SCT.Maximum)])
    report = hd.sr.MeasurementReport(
        observation_context=hd.sr.ObservationContext(observer_device_context=device),
        procedure_reported=codes.LN.CTUnspecifiedBodyRegion, imaging_measurements=[planar, image])
    hd.sr.Comprehensive3DSR(
        evidence=[src], content=report[0], series_number=1, series_instance_uid=hd.UID(),
        sop_instance_uid=hd.UID(), instance_number=1, manufacturer="test").save_as(out)


if sys.argv[1] == "read":
    read(sys.argv[2])
else:
    write(sys.argv[2], sys.argv[3])
