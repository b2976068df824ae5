/*
 * Trigger-box firmware: build-time settings and the pin map (ATmega328P at 16 MHz, Arduino Uno
 * or Nano). docs/trigger-box.md has the wiring; docs/trigger-box-protocol.md the protocol.
 */
#ifndef TRIGGER_BOX_CONFIG_H
#define TRIGGER_BOX_CONFIG_H

#ifndef F_CPU
#define F_CPU 16000000UL
#endif

#ifndef FW_VERSION
#define FW_VERSION "0.1.0"
#endif
/* Protocol version this firmware speaks (1 plus V, `#` lines and the host-silence fail-safe). */
#define PROTOCOL_VERSION "2"

/* ---- Pin map ------------------------------------------------------------------------------ */
/* D9  = PB1 = OC1A: camera trigger, active high, CAMERA_PULSE_US wide (Timer1 compare output). */
/* D10 = PB2 = OC1B: light strobe, active high (Timer1 compare output).                        */
/* D3  = PD3 = OC2B: light level, PWM (Timer2, LIGHT_PWM_HZ).                                   */
/* D4  = PD4: e-stop input, normally-closed contact to GND, internal pull-up: high = pressed.    */
/* D5  = PD5: door input, normally-closed contact to GND, internal pull-up: high = open.        */
/* D13 = PB5: status LED (on: a host is talking; blinking 1 Hz: fail-safe, no host).            */
#define CAM_BIT PB1
#define STROBE_BIT PB2
#define LED_BIT PB5
#define LIGHT_BIT PD3
#define ESTOP_BIT PD4
#define DOOR_BIT PD5

/* ---- Timing ------------------------------------------------------------------------------- */
/* Timer1 runs free at F_CPU / 8: one tick is 0.5 us; device_us = ticks / 2. */
#define TICKS_PER_US 2
/* Camera pulse width (the Orbbec sync input takes a rising edge; 1 ms is wide enough for any
 * input filter and far shorter than a frame). At least 50 us. */
#ifndef CAMERA_PULSE_US
#define CAMERA_PULSE_US 1000UL
#endif
/* Ticks from reading TCNT1 to the edge it schedules: covers the instructions that program the
 * compare unit (the code checks it was in time). 8 ticks = 4 us. */
#define FIRE_LEAD_TICKS 8
/* A flash end closer than this to "now" (ticks) is waited for in the ISR instead of being left
 * to the compare unit. */
#define SHORT_TICKS 40

/* Inputs are sampled every 1 ms; a new level counts once it was read on DEBOUNCE_SAMPLES
 * consecutive samples (4..5 ms stable). */
#define DEBOUNCE_SAMPLES 5
/* An `I` line at least this often (ms); the protocol asks for <= 50 ms. */
#define INPUT_REPORT_MS 20
/* No valid command from the host for this long (ms): fail-safe (camera low, light safe). */
#define HOST_SILENCE_MS 1000UL
/* Light level of the fail-safe state and at power-up, permille (0 = off). */
#define SAFE_LEVEL_PERMILLE 0
/* Light PWM: Timer2 fast PWM, prescaler 1: 16 MHz / 256 = 62.5 kHz. */
#define LIGHT_PWM_HZ 62500UL

/* ---- Link --------------------------------------------------------------------------------- */
/* 115200 baud: U2X, UBRR 16 -> 117647 baud (+2.1 %), as every 16 MHz Arduino does it. */
#define UART_UBRR 16
#define MAX_LINE 64 /* bytes including '\n', both directions */

#endif
