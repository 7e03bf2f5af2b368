// accel_stream.ino - the accelerometer board of the heave-compensation framework (thesis 4.2.3).
// An Arduino Uno reads an MPU-6050 over I2C (SDA = A4, SCL = A5, VCC = 3.3 V or 5 V module, GND),
// low-pass filters the acceleration (first order, cut-off FC_HZ), computes roll and pitch and
// sends one line per sample over USB serial at 115200 Bd:  <millis>,<roll deg>,<pitch deg>\n
// This is the format pyopenshowvar_apps.heave.accel.AccelReader parses (kvp heave --accel PORT).
// Mount the board flat on the platform's top plate, x towards the robot's front (away from
// corner 1), y to the left, so roll is about x and pitch about y as in docs/heave.md.
#include <Wire.h>
#include <math.h>

const uint8_t MPU = 0x68;          // AD0 low
const float RATE_HZ = 100.0;       // sample and send rate
const float FC_HZ = 5.0;           // low-pass cut-off (the server undoes its ~32 ms delay)
const float LSB_PER_G = 16384.0;   // +-2 g range
float fx = 0, fy = 0, fz = 1;
float alpha;
unsigned long next_us;

void setup() {
  Serial.begin(115200);
  Wire.begin();
  Wire.beginTransmission(MPU); Wire.write(0x6B); Wire.write(0); Wire.endTransmission();  // wake
  Wire.beginTransmission(MPU); Wire.write(0x1A); Wire.write(3); Wire.endTransmission();  // DLPF 44 Hz
  alpha = 1.0 - exp(-2.0 * M_PI * FC_HZ / RATE_HZ);
  next_us = micros();
}

static int16_t word_at() { int16_t hi = Wire.read(); return (hi << 8) | Wire.read(); }

void loop() {
  if ((long)(micros() - next_us) < 0) return;
  next_us += (unsigned long)(1e6 / RATE_HZ);
  Wire.beginTransmission(MPU); Wire.write(0x3B); Wire.endTransmission(false);
  Wire.requestFrom(MPU, (uint8_t)6);
  float ax = word_at() / LSB_PER_G, ay = word_at() / LSB_PER_G, az = word_at() / LSB_PER_G;
  fx += alpha * (ax - fx); fy += alpha * (ay - fy); fz += alpha * (az - fz);
  float roll = atan2(fy, fz) * 180.0 / M_PI;
  float pitch = atan2(-fx, sqrt(fy * fy + fz * fz)) * 180.0 / M_PI;
  Serial.print(millis()); Serial.print(',');
  Serial.print(roll, 3); Serial.print(',');
  Serial.println(pitch, 3);   // println ends with \r\n; the reader strips the \r
}
